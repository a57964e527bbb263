#include "recon_cuda/run/time_plan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "common/errors.h"

namespace perf::recon {
namespace {

// A later level's seconds from the one before: its rays times twice the samples per ray (the
// grid doubles); lego 50 x 50, 32^3 to 64^3 with bands: 1.9x measured (docs/tuning.md "Time budget").
constexpr double kLevelGrowth = 2.0;
// The stages after the solve at a later level than they were measured at: the masks' renders
// march a finer grid.
constexpr double kReserveGrowth = 1.25;

// Seconds for the terminal: 0.95, 12.3.
std::string Sec(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, std::abs(v) < 10 ? "%.2f" : "%.1f", v);
  return buf;
}

int Fit(double seconds, double each, int at_most) {
  if (at_most <= 0 || seconds <= 0) return 0;
  return static_cast<int>(std::min<double>(at_most, std::floor(seconds / std::max(each, 1e-6))));
}

}  // namespace

std::vector<int> PlanIterations(double seconds, std::span<const LevelEstimate> levels) {
  const size_t n = levels.size();
  std::vector<int> plan(n, 0);
  if (n == 0) return plan;
  double all = 0;
  for (const LevelEstimate& l : levels) all += l.setup + l.iterations * l.iteration;
  if (all <= seconds) {
    for (size_t j = 0; j < n; ++j) plan[j] = levels[j].iterations;
    return plan;
  }
  for (size_t last = n - 1; last > 0; --last) {
    std::fill(plan.begin(), plan.end(), 0);
    const double share = seconds * (1 - kFinestShare) / static_cast<double>(last);
    double used = 0;
    for (size_t j = 0; j < last; ++j) {
      const LevelEstimate& l = levels[j];
      plan[j] = std::max(std::min(1, l.iterations), Fit(share - l.setup, l.iteration, l.iterations));
      used += l.setup + plan[j] * l.iteration;
    }
    const LevelEstimate& f = levels[last];
    const int finest = Fit(seconds - used - f.setup, f.iteration, f.iterations);
    if (finest < std::min(kMinFinestIterations, f.iterations)) continue;
    plan[last] = finest;
    // The finest level at its cap: the time it leaves goes to the levels before, coarse first.
    double left = seconds - used - f.setup - finest * f.iteration;
    for (size_t j = 0; j < last && left > 0; ++j) {
      const int more = Fit(left, levels[j].iteration, levels[j].iterations - plan[j]);
      plan[j] += more;
      left -= more * levels[j].iteration;
    }
    return plan;
  }
  std::fill(plan.begin(), plan.end(), 0);
  plan[0] = std::max(std::min(1, levels[0].iterations), Fit(seconds - levels[0].setup, levels[0].iteration,
                                                             levels[0].iterations));
  return plan;
}

TimePlanner::TimePlanner(TimeBudget budget, int start_resolution, std::vector<int> level_caps,
                         std::vector<int64_t> level_rays)
    : budget_(std::move(budget)),
      start_resolution_(start_resolution),
      caps_(std::move(level_caps)),
      rays_(std::move(level_rays)),
      levels_(caps_.size()) {
  PERF_CHECK(rays_.size() == caps_.size());
}

double TimePlanner::Now() const { return SecondsSince(budget_.start); }

double TimePlanner::SecondsLeft(double reserve) const {
  return budget_.seconds * (1 - kBudgetMargin) - Now() - reserve;
}

double TimePlanner::ReserveAt(int level) const {
  if (reserve_level_ < 0) return 0;
  return reserve_ * std::pow(kReserveGrowth, std::max(0, level - reserve_level_));
}

std::vector<int> TimePlanner::PlanFrom(int level, int done) const {
  return PlanIterations(SecondsLeft(ReserveAt(static_cast<int>(levels_.size()) - 1)), Estimates(level, done));
}

std::vector<LevelEstimate> TimePlanner::Estimates(int from, int done) const {
  std::vector<LevelEstimate> out;
  int base = -1;  // the last level measured
  for (int j = 0; j < static_cast<int>(levels_.size()); ++j) {
    if (levels_[j].iteration >= 0) base = j;
  }
  for (int j = from; j < static_cast<int>(levels_.size()); ++j) {
    LevelEstimate e;
    e.iterations = caps_[j] - (j == from ? done : 0);
    const Level& l = levels_[j];
    if (l.iteration >= 0) {
      e.iteration = l.iteration;
      e.setup = j == from && done > 0 ? 0 : l.setup;
    } else if (base >= 0) {
      const Level& b = levels_[base];
      const double factor = std::pow(kLevelGrowth, j - base) * static_cast<double>(rays_[j]) /
                            static_cast<double>(std::max<int64_t>(1, rays_[base]));
      e.iteration = b.iteration * factor;
      e.setup = b.setup * factor;
    }
    out.push_back(e);
  }
  return out;
}

bool TimePlanner::BeforeLevel(int level) {
  Level& l = levels_[level];
  l.begun = Now();
  if (level == 0) {
    solve_start_ = l.begun;
    return true;
  }
  const int last = static_cast<int>(levels_.size()) - 1;
  const std::vector<LevelEstimate> e = Estimates(level, 0);
  const double left = SecondsLeft(ReserveAt(last));
  // The level runs where its setup and its minimum fit (PlanIterations shares the time once it runs).
  if (left >= e[0].setup + std::min(kMinFinestIterations, e[0].iterations) * e[0].iteration) return true;
  stopped_ = StrCat("level ", level + 1, " (", start_resolution_ << level, "^3, about ", Sec(e[0].iteration),
                    " s an iteration) would not get ", kMinFinestIterations, " iterations in the ", Sec(std::max(0.0, left)),
                    " s the budget leaves; the run ends at level ", level);
  message_ = "time plan: " + stopped_;
  return false;
}

void TimePlanner::LevelStarted(int level) {
  Level& l = levels_[level];
  l.setup = Now() - l.begun;
  l.last = Now();
}

PlanVerdict TimePlanner::AfterIteration(int level, int done, const std::function<double()>& measure_after) {
  Level& l = levels_[level];
  const double now = Now();
  const double seconds = now - l.last;
  // The first iteration also records the Jacobian's cache: what it takes beyond the second counts
  // as the level's setup. Later ones are smoothed over about three.
  if (done == 1) {
    l.first = seconds;
    l.iteration = seconds;
  } else if (done == 2) {
    l.iteration = seconds;
    l.setup += std::max(0.0, l.first - seconds);
  } else {
    l.iteration = (2 * l.iteration + seconds) / 3;
  }
  l.ran = done;
  if (done == 1 && measure_after) {
    reserve_ = measure_after();
    reserve_level_ = level;
  }
  // The plan for the level is fixed at its second iteration (its first where it has one).
  if (done == std::min(2, caps_[level])) {
    const std::vector<int> plan = PlanFrom(level, done);
    l.planned = done + plan[0];
    later_planned_ = std::any_of(plan.begin() + 1, plan.end(), [](int n) { return n > 0; });
    const std::string line = Describe(level, plan);
    if (first_plan_.is_null()) first_plan_ = {{"at_level", level}, {"seconds", now}, {"plan", line}};
    message_ = "time plan: " + line;
  }
  l.last = Now();
  if (done >= caps_[level]) return PlanVerdict::kGoOn;  // the level ends by itself
  // The first level's floor: the plan may move on to the next level before it, but not end the run.
  const bool floor = level == 0 && done < kMinFirstIterations;
  // An iteration more would pass the budget's end: the run ends here, whatever the plan said.
  if (!floor && l.last + l.iteration + ReserveAt(level) > budget_.seconds) {
    stopped_ = StrCat("the budget's end is near at level ", level + 1, " iteration ", done, " (", Sec(l.last),
                      " s spent, about ", Sec(l.iteration), " s an iteration, export and eval ~", Sec(ReserveAt(level)),
                      " s): the run ends at this level");
    message_ = "time plan: " + stopped_;
    return PlanVerdict::kStop;
  }
  if (l.planned < 0 || done < l.planned) return PlanVerdict::kGoOn;
  if (later_planned_) return PlanVerdict::kEndLevel;
  // The plan's finest level ran its iterations: where they went faster than planned, the time
  // left goes to a finer level that now fits, or else to more of this one.
  const std::vector<int> plan = PlanFrom(level, done);
  if (std::any_of(plan.begin() + 1, plan.end(), [](int n) { return n > 0; })) {
    message_ = StrCat("time plan: level ", level + 1, " ran its ", l.planned, " planned iterations sooner than planned; ",
                      "level ", level + 2, " fits in the time left");
    return PlanVerdict::kEndLevel;
  }
  // One more where it fits with half an iteration to spare (the estimates of export and eval
  // miss the mesh: lego 50 x 50 ended at 63.9 of 60 s without the spare).
  if (plan[0] > 0 && SecondsLeft(ReserveAt(level)) > 1.5 * l.iteration) {
    l.planned = done + 1;  // one more, then look again
    return PlanVerdict::kGoOn;
  }
  if (floor) return PlanVerdict::kGoOn;
  stopped_ = StrCat("level ", level + 1, " ran its ", done, " iterations in the budget");
  message_ = "time plan: " + stopped_ + "; the run ends here";
  return PlanVerdict::kStop;
}

std::string TimePlanner::TakeMessage() {
  std::string m;
  m.swap(message_);
  return m;
}

std::string TimePlanner::Describe(int from, const std::vector<int>& plan) const {
  const std::vector<LevelEstimate> e = Estimates(from, 0);
  std::string s = StrCat("budget ", Sec(budget_.seconds), " s, ", Sec(Now()), " s spent");
  double end = Now();
  int finest = from;
  for (size_t k = 0; k < plan.size(); ++k) {
    const int level = from + static_cast<int>(k);
    const bool measured = levels_[level].iteration >= 0;
    if (plan[k] == 0) {
      s += StrCat("; level ", level + 1, " left out");
      continue;
    }
    finest = level;
    const int ran = level == from ? levels_[level].ran : 0;
    s += StrCat("; level ", level + 1, " (", start_resolution_ << level, "^3): ", ran + plan[k], " iterations of ",
                measured ? "" : "~", Sec(e[k].iteration), " s", measured ? "" : " (estimated)");
    end += (level == from ? 0 : e[k].setup) + plan[k] * e[k].iteration;
  }
  end += ReserveAt(finest);
  s += StrCat("; export and eval ~", Sec(ReserveAt(finest)), " s (measured on one photo); ends at ~", Sec(end), " s");
  return s;
}

nlohmann::json TimePlanner::ToJson() const {
  nlohmann::json levels = nlohmann::json::array();
  for (size_t j = 0; j < levels_.size(); ++j) {
    const Level& l = levels_[j];
    if (l.setup < 0) continue;
    levels.push_back({{"level", j},
                      {"n", start_resolution_ << j},
                      {"planned_iterations", l.planned},
                      {"iterations", l.ran},
                      {"setup_seconds", l.setup},
                      {"seconds_per_iteration", l.iteration}});
  }
  return {{"budget_seconds", budget_.seconds},
          {"solve_started_at", solve_start_},
          {"solve_ended_at", Now()},
          {"after_solve_seconds", reserve_},
          {"after_solve_measured_at_level", reserve_level_},
          {"first_plan", first_plan_},
          {"levels", levels},
          {"stopped", stopped_}};
}

}  // namespace perf::recon
