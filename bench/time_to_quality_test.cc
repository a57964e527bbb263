// The GPU benchmark's engine on the CPU backend (it is backend-agnostic), on a tiny synthetic
// scene: the JSON and SVG on disk are complete after every evaluation and every level (what a
// run killed by a time limit leaves), a time budget and a stop flag end a run at the next solver
// iteration with its results kept. A fake clock makes the budget deterministic.
#include "bench/time_to_quality.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "common/atomic_file.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "tests/recon/synthetic_scene.h"

namespace perf::bench {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using recon::SolverType;

// 12 views of 16 x 16 of the synthetic scene as 8-bit photos, every 4th held out.
BenchData TinyData() {
  const recon::test::SyntheticScene scene(8, 4, 12, 16, 4);
  BenchData d;
  d.geometry = scene.geometry;
  for (const auto* split : {&scene.train, &scene.test}) {
    for (const recon::PosedImage& im : *split) {
      View v;
      v.name = im.name;
      v.train = split == &scene.train;
      v.camera = im.camera;
      v.width = im.image.width;
      v.height = im.image.height;
      d.views.push_back(v);
      for (float c : im.image.pixels) {
        d.pixels.push_back(static_cast<uint8_t>(std::lround(std::clamp(c, 0.f, 1.f) * 255)));
      }
    }
  }
  int64_t offset = 0;
  for (View& v : d.views) {
    v.rgb = d.pixels.data() + offset;
    offset += int64_t{3} * v.width * v.height;
  }
  return d;
}

BenchSettings TinySettings() {
  BenchSettings s;
  s.levels = 2;
  s.start = 4;
  s.gn_iterations = 3;
  s.adam_steps = 6;
  s.adam_eval_every = 2;
  s.solver.psnr_ray_stride = 0;
  return s;
}

class TimeToQualityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = fs::path(::testing::TempDir()) / ("ttq_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir);
    recon::CpuBackendOptions o;
    o.threads = 2;
    backend = recon::MakeCpuBackend(o);
  }
  void TearDown() override { fs::remove_all(dir); }

  // A clock that moves by `step` seconds whenever it is read.
  std::function<double()> FakeClock(double step) {
    return [this, step] { return now += step; };
  }
  json ReadJson(const ResultsFiles& files) { return json::parse(ReadFileToString(files.json_path)); }

  fs::path dir;
  std::unique_ptr<recon::Backend> backend;
  const BenchData data = TinyData();
  const BenchSettings settings = TinySettings();
  const json header{{"format", "perf-bench-gpu"}, {"device", "cpu"}};
  double now = 0;
};

TEST_F(TimeToQualityTest, WritesTheResultsAfterEveryEvaluationAndEveryLevel) {
  const ResultsFiles files(dir, "tiny");
  std::map<std::string, SolverRun> runs;
  for (SolverType type : {SolverType::kGaussNewton, SolverType::kAdam}) {
    const std::string name = recon::SolverName(type);
    int updates = 0;
    RunContext ctx;
    ctx.clock = FakeClock(0.25);
    ctx.on_update = [&](const SolverRun& r) {
      ++updates;
      runs[name] = r;
      files.Write(header, runs, 1000, "cpu");
      // What is on disk now is whole and says as much as the run has.
      const json j = ReadJson(files);
      ASSERT_TRUE(j["runs"].contains(name));
      EXPECT_EQ(j["runs"][name]["points"].size(), r.points.size());
      EXPECT_EQ(j["runs"][name]["levels"].size(), r.levels.size());
      EXPECT_EQ(j["runs"][name]["final_test_psnr"].get<double>(), r.final_psnr);
      const std::string svg = ReadFileToString(files.svg_path);
      EXPECT_EQ(svg.rfind("<svg", 0), 0u) << svg.substr(0, 80);
      EXPECT_NE(svg.find("</svg>"), std::string::npos);
      // Written through temporaries renamed into place: nothing else is left in the folder.
      int entries = 0;
      for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++entries;
      EXPECT_EQ(entries, 2);
    };
    SolverRun run;
    RunHierarchy(backend.get(), data, type, settings, ctx, &run);
    // GN evaluates after each of its 3 iterations per level, Adam after steps 2, 4 and 6; plus
    // one write per level.
    const int evaluations = 2 * 3;
    EXPECT_EQ(static_cast<int>(run.points.size()), evaluations) << name;
    EXPECT_EQ(updates, evaluations + 2) << name;
    EXPECT_TRUE(run.complete) << name;
    EXPECT_TRUE(run.stopped.empty()) << name;
    ASSERT_EQ(run.levels.size(), 2u);
    EXPECT_EQ(run.passes.size(), 2u);
    EXPECT_GT(run.final_psnr, 10) << name;
    EXPECT_GT(run.seconds, 0) << name;
    // Solver time never runs backwards.
    for (size_t i = 1; i < run.curve.size(); ++i) EXPECT_GE(run.curve[i].first, run.curve[i - 1].first);
  }
  const json j = ReadJson(files);
  EXPECT_TRUE(j["runs"]["gn"]["complete"].get<bool>());
  EXPECT_TRUE(j["runs"]["adam"]["stopped"].is_null());
  EXPECT_EQ(j["roofline"]["level"], 1);
  EXPECT_GT(j["roofline"]["measured_cost_pass_samples_per_s"].get<double>(), 0);
  EXPECT_GT(j["roofline"]["bound_no_reuse_samples_per_s"].get<double>(), 0);
  EXPECT_TRUE(j.contains("adam_over_gn_time_to_95pct"));
}

TEST_F(TimeToQualityTest, ATimeBudgetStopsAtTheNextIterationAndKeepsTheResults) {
  // The whole GN run on this clock, noting the time of every update; then the same run with the
  // deadline at the first evaluation of level 1 (updates: 3 evaluations and the end of level 0,
  // then that one).
  RunContext ctx;
  ctx.clock = FakeClock(1.0);
  std::vector<double> update_times;
  ctx.on_update = [&](const SolverRun&) { update_times.push_back(now); };
  SolverRun full;
  RunHierarchy(backend.get(), data, SolverType::kGaussNewton, settings, ctx, &full);
  ASSERT_TRUE(full.complete);
  ASSERT_EQ(update_times.size(), 8u);

  const ResultsFiles files(dir, "budget");
  std::map<std::string, SolverRun> runs;
  now = 0;
  ctx.deadline = update_times[4];
  ctx.on_update = [&](const SolverRun& r) {
    runs["gn"] = r;
    files.Write(header, runs, 0, "cpu");
  };
  SolverRun run;
  RunHierarchy(backend.get(), data, SolverType::kGaussNewton, settings, ctx, &run);
  EXPECT_EQ(run.stopped, "time budget");
  EXPECT_FALSE(run.complete);
  // Level 1 stopped after its second iteration, the first to end past the deadline.
  ASSERT_EQ(run.levels.size(), 2u);
  EXPECT_EQ(run.levels[1]["stopped"], "time budget");
  EXPECT_EQ(run.levels[1]["iterations"], 2);
  EXPECT_EQ(run.points.size(), 5u);
  EXPECT_EQ(run.passes.size(), 1u);  // level 0's throughput; none for the stopped level
  // The last write holds everything the run returned.
  json j = ReadJson(files);
  EXPECT_EQ(j["runs"]["gn"]["points"].size(), run.points.size());
  EXPECT_EQ(j["runs"]["gn"]["levels"].size(), run.levels.size());
  EXPECT_EQ(j["runs"]["gn"]["stopped"], "time budget");
  EXPECT_FALSE(j["runs"]["gn"]["complete"].get<bool>());
  EXPECT_EQ(j["roofline"]["level"], 0);

  // The deadline passed at the end of a level: the next level does not start, and the file says
  // why the run ended.
  now = 0;
  runs.clear();
  ctx.deadline = update_times[3] - 0.5;
  SolverRun between;
  RunHierarchy(backend.get(), data, SolverType::kGaussNewton, settings, ctx, &between);
  EXPECT_EQ(between.stopped, "time budget");
  ASSERT_EQ(between.levels.size(), 1u);
  EXPECT_FALSE(between.levels[0].contains("stopped"));
  j = ReadJson(files);
  EXPECT_EQ(j["runs"]["gn"]["stopped"], "time budget");
  EXPECT_EQ(j["runs"]["gn"]["levels"].size(), 1u);
}

TEST_F(TimeToQualityTest, AStopFlagEndsTheRunAtTheNextIteration) {
  std::atomic<bool> stop{false};
  RunContext ctx;
  ctx.stop = &stop;
  ctx.on_update = [&](const SolverRun&) { stop.store(true); };  // "SIGTERM" after the first evaluation
  SolverRun run;
  RunHierarchy(backend.get(), data, SolverType::kGaussNewton, settings, ctx, &run);
  EXPECT_EQ(run.stopped, "signal");
  EXPECT_EQ(run.points.size(), 2u);  // the first iteration, and the one during which it stopped
  ASSERT_EQ(run.levels.size(), 1u);
  EXPECT_EQ(run.levels[0]["iterations"], 2);
  EXPECT_EQ(run.levels[0]["stopped"], "signal");
  EXPECT_TRUE(run.passes.empty());  // no throughput probes when stopping
}

}  // namespace
}  // namespace perf::bench
