// A run's time budget (perf run --time-budget): which levels run and for how many iterations, so
// that the whole run ends by its deadline. The first iteration of each level is timed and the
// stages after the solve are measured (TimeBudget::after_solve) before the level's iterations are
// fixed; a later level is estimated from the one before (twice its seconds per ray) until it runs.
// Where every level's iterations fit, the plan changes nothing. Where they do not, the finest level
// that still gets kMinFinestIterations gets kFinestShare of the time left, the levels before it
// the rest, and each level still ends early where its cost flattens (SolverOptions::cost_tolerance).
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "common/stopwatch.h"
#include "recon_cuda/solve/backend.h"

namespace perf {
struct Scene;
}

namespace perf::recon {

// The finest level of a plan runs at least this many iterations (fewer: the level before ends the
// run); it gets this share of the time left when the levels' iterations do not all fit.
inline constexpr int kMinFinestIterations = 4;
// The first level runs at least this many iterations (or its cap) even past the budget's end, unless
// the plan moves on to the next level sooner: a run whose budget went to the stages before the
// solve (perf sfm) still ends with the object's figure.
inline constexpr int kMinFirstIterations = 8;
inline constexpr double kFinestShare = 2.0 / 3.0;
// The plan aims this fraction of the budget before the deadline (what the estimates miss).
inline constexpr double kBudgetMargin = 0.04;

struct TimeBudget {
  double seconds = 0;               // the whole run's budget
  WallClock::time_point start;      // when it began counting (the run's start)
  // Estimated seconds of the stages after the solve (perf run: export and eval) from the level's
  // current parameters, measured by doing their work for one photo; unset: none follow.
  std::function<double(Backend* backend, VecId params, const Scene& scene)> after_solve;

  WallClock::time_point Deadline() const {
    return start + std::chrono::duration_cast<WallClock::duration>(std::chrono::duration<double>(seconds));
  }
};

// What a level will cost, for a plan.
struct LevelEstimate {
  double setup = 0;      // seconds before its first iteration (0 once paid)
  double iteration = 0;  // seconds per iteration
  int iterations = 0;    // at most (its cap, less those done)
};

// Iterations for each level of `levels` (the next first) within `seconds`: every cap when they all
// fit; else the levels up to the finest that still gets kMinFinestIterations, the earlier ones
// sharing (1 - kFinestShare) of the time equally (at least one iteration each) and the finest the
// rest; the levels past it get 0. The first level gets at least one iteration.
std::vector<int> PlanIterations(double seconds, std::span<const LevelEstimate> levels);

// What the planner tells the hierarchy after an iteration.
enum class PlanVerdict { kGoOn, kEndLevel, kStop };

// The plan of one run, kept by LevelMonitor through the hierarchy's callbacks. Times are wall
// clock (the budget is the user's). Single process: under mpirun the budget is not applied.
class TimePlanner {
 public:
  // level_caps: each level's iteration cap; level_rays: each level's training rays (its pyramid
  // downscale), which scale a later level's estimate from the one before.
  TimePlanner(TimeBudget budget, int start_resolution, std::vector<int> level_caps, std::vector<int64_t> level_rays);

  // Before level `level` is set up: false ends the run at the level before (its estimate does not
  // fit kMinFinestIterations in the time left). `why` then says so.
  bool BeforeLevel(int level);
  void LevelStarted(int level);
  // After iteration `done` (1-based) of `level`; `measure_after` measures the stages after the
  // solve (called at each level's first iteration, where the plan for the level is fixed).
  PlanVerdict AfterIteration(int level, int done, const std::function<double()>& measure_after);

  // The plan's line for the terminal, once per level (empty when it has not changed).
  std::string TakeMessage();
  const std::string& stopped() const { return stopped_; }
  // For recon.json and run.json: the budget, each level's planned and run iterations and measured
  // seconds, the stages after the solve as measured, and why the plan ended the run, if it did.
  nlohmann::json ToJson() const;

 private:
  double Now() const;  // seconds since the budget's start
  double SecondsLeft(double reserve) const;
  std::vector<LevelEstimate> Estimates(int from, int done) const;
  // The plan from `level` (`done` of its iterations run) in the time left less the finest
  // level's export and eval.
  std::vector<int> PlanFrom(int level, int done) const;
  double ReserveAt(int level) const;
  std::string Describe(int from, const std::vector<int>& plan) const;

  TimeBudget budget_;
  int start_resolution_ = 32;
  std::vector<int> caps_;
  std::vector<int64_t> rays_;
  struct Level {
    double setup = -1, iteration = -1;  // measured (-1: not yet)
    double first = 0;                   // the first iteration's seconds
    int planned = -1, ran = 0;
    double begun = 0, last = 0;  // Now() at BeforeLevel and at the last iteration
  };
  std::vector<Level> levels_;
  double reserve_ = 0;      // the stages after the solve, as last measured
  int reserve_level_ = -1;  // at this level
  double solve_start_ = 0;  // Now() when the first level began
  bool later_planned_ = false;  // the current level's plan has levels after it
  std::string message_, stopped_;
  nlohmann::json first_plan_;
};

}  // namespace perf::recon
