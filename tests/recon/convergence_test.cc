// Convergence of the whole solver on a known scene (synthetic_scene.h): from a random start,
// through two levels of the hierarchy, to a high held-out PSNR, with the Gauss-Newton cost
// falling at every iteration of the coarse level. Plus the solver's contract: options checks,
// callbacks, statuses, and the Adam baseline on the same passes.
#include <gtest/gtest.h>

#include "common/errors.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/data/volume.h"
#include "recon_cuda/run/evaluation.h"
#include "recon_cuda/solve/solver.h"
#include "tests/recon/synthetic_scene.h"

namespace perf::recon {
namespace {

const test::SyntheticScene& Scene() {
  // 36 views of 48 x 48 on a sphere, every 6th held out; the truth is a 32^3 grid.
  static const test::SyntheticScene scene(32, 16, 36, 48, 6);
  return scene;
}

// The scene's training rays on a CPU backend.
class ConvergenceTest : public ::testing::Test {
 protected:
  // Makes `shape` the backend's level with `vectors` vectors.
  void SetLevel(const VolumeShape& shape, int vectors) {
    backend->SetLevel(LevelProblem{shape, scene.geometry, &rays, {}}, vectors);
  }
  std::vector<float> RandomStart(const VolumeShape& shape) const {
    return InitialParams(shape, scene.geometry, InitOptions{});
  }

  const test::SyntheticScene& scene = Scene();
  std::unique_ptr<Backend> backend = MakeCpuBackend({});
  const RaySet rays = MakeRaySet(scene.train);
};
using SolverTest = ConvergenceTest;

// Exact Gauss-Newton, and subsampled (J^T J p on every 4th ray, SolverOptions::jtj_ray_stride).
class GaussNewtonTest : public ConvergenceTest, public ::testing::WithParamInterface<int> {};

TEST_P(GaussNewtonTest, RecoversAKnownScene) {
  VolumeShape shape{16, 8, 2};
  std::vector<float> x = RandomStart(shape);
  const double start_psnr = [&] {
    SetLevel(shape, 1);
    backend->Upload(0, x);
    return MeanPsnr(ScoreViews(backend.get(), 0, scene.test, 0.f));
  }();
  SolverOptions so;
  so.max_iterations = 15;
  so.jtj_ray_stride = GetParam();
  for (int level = 0; level < 2; ++level) {
    SetLevel(shape, RequiredVectors(so.type));
    so.seed = 100 + level;
    SolverSummary summary;
    Solve(so, backend.get(), &x, {}, &summary);
    ASSERT_EQ(summary.iterations, 15);
    EXPECT_EQ(summary.status, SolverStatus::kIterationLimit);
    if (level == 0) {
      // Far from the solution, every Gauss-Newton step lowers the cost by much more than the
      // change of jitter between iterations moves it: the cost falls strictly.
      for (size_t i = 0; i < summary.per_iteration.size(); ++i) {
        const IterationSummary& s = summary.per_iteration[i];
        EXPECT_TRUE(s.accepted) << "iteration " << i;
        EXPECT_LT(s.cost_after, s.cost) << "iteration " << i;
        if (i > 0) {
          EXPECT_LT(s.cost, summary.per_iteration[i - 1].cost) << "iteration " << i;
        }
      }
      EXPECT_LT(summary.final_cost, 0.05 * summary.initial_cost);
      x = Resample(shape, x, shape.Doubled());
      shape = shape.Doubled();
    }
  }
  const double psnr = MeanPsnr(ScoreViews(backend.get(), VectorsOf(so.type).params, scene.test, 0.f));
  std::printf("held-out PSNR: %.2f dB from a random start at %.2f dB\n", psnr, start_psnr);
  // The truth is exactly representable at the final level (32^3), so the bar is the issue's
  // 30 dB (RMS error ~3 %), leaving ~6 dB for the 15 + 15 iterations and the jitter.
  EXPECT_GT(psnr, 30.0);
  EXPECT_LT(start_psnr, 15.0);
}

INSTANTIATE_TEST_SUITE_P(JtJRayStride, GaussNewtonTest, ::testing::Values(1, 4));

TEST_F(ConvergenceTest, AdamRunsOnTheSamePasses) {
  const VolumeShape shape{16, 8, 2};
  std::vector<float> x = RandomStart(shape);
  SolverOptions so;
  so.type = SolverType::kAdam;
  so.max_iterations = 40;
  so.adam.lr_density = 0.3f;
  SetLevel(shape, RequiredVectors(so.type));
  SolverSummary summary;
  Solve(so, backend.get(), &x, {}, &summary);
  EXPECT_EQ(summary.linearize_passes, 40);
  EXPECT_EQ(summary.jtj_passes, 0);
  EXPECT_LT(summary.final_cost, 0.2 * summary.initial_cost);
  for (float v : x) ASSERT_GE(v, 0.f);  // projected after every step
}

TEST_F(SolverTest, OptionsAreChecked) {
  SolverOptions o;
  EXPECT_NO_THROW(o.Check());
  o.step_factor = 1.0;
  try {
    o.Check();
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "step_factor");
  }
  o = SolverOptions();
  o.max_cg_iterations = 0;
  EXPECT_THROW(o.Check(), InputError);
  o = SolverOptions();
  o.damping = -1;
  EXPECT_THROW(o.Check(), InputError);
  for (int stride : {0, 65}) {
    o = SolverOptions();
    o.jtj_ray_stride = stride;
    EXPECT_THROW(o.Check(), InputError) << stride;
  }
  for (double tolerance : {-0.01, 1.0}) {
    o = SolverOptions();
    o.cost_tolerance = tolerance;
    EXPECT_THROW(o.Check(), InputError) << tolerance;
  }
  o = SolverOptions();
  o.cost_tolerance_window = 0;
  EXPECT_THROW(o.Check(), InputError);
}

// SolverOptions::cost_tolerance: the level ends at the first iteration whose cost is within the
// tolerance of the cost a window before, and not earlier; 0 (and Adam) run every iteration.
TEST_F(SolverTest, ConvergedStopsWhereTheCostFlattens) {
  const VolumeShape shape{8, 4, 2};
  SetLevel(shape, RequiredVectors(SolverType::kGaussNewton));
  SolverOptions so;
  so.max_iterations = 30;
  so.cost_tolerance = 0.01;
  const int w = so.cost_tolerance_window;
  std::vector<float> x = RandomStart(shape);
  SolverSummary summary;
  Solve(so, backend.get(), &x, {}, &summary);
  ASSERT_EQ(summary.status, SolverStatus::kConverged) << summary.BriefReport();
  const std::vector<IterationSummary>& its = summary.per_iteration;
  const int n = summary.iterations;
  ASSERT_GT(n, w);
  EXPECT_LT(n, so.max_iterations);
  const auto fell = [&](int i) { return (its[i - w].cost - its[i].cost) / its[i].cost; };
  EXPECT_LT(fell(n - 1), so.cost_tolerance);
  for (int i = w; i < n - 1; ++i) EXPECT_GE(fell(i), so.cost_tolerance) << "iteration " << i;
  EXPECT_NE(summary.BriefReport().find("converged"), std::string::npos) << summary.BriefReport();

  so.cost_tolerance = 0;
  so.max_iterations = n + 2;
  x = RandomStart(shape);
  Solve(so, backend.get(), &x, {}, &summary);
  EXPECT_EQ(summary.status, SolverStatus::kIterationLimit);
  EXPECT_EQ(summary.iterations, n + 2);

  so.type = SolverType::kAdam;
  so.cost_tolerance = 0.5;
  SetLevel(shape, RequiredVectors(so.type));
  x = RandomStart(shape);
  Solve(so, backend.get(), &x, {}, &summary);
  EXPECT_EQ(summary.iterations, n + 2);
}

TEST_F(SolverTest, CallbackStopsAndSummaryReports) {
  const VolumeShape shape{8, 4, 2};
  std::vector<float> x = RandomStart(shape);
  SetLevel(shape, RequiredVectors(SolverType::kGaussNewton));
  SolverOptions so;
  so.max_iterations = 10;
  so.line_search_ray_stride = 4;
  int calls = 0;
  SolverSummary summary;
  Solve(so, backend.get(), &x, [&](const IterationSummary& s) {
    EXPECT_EQ(s.iteration, calls);
    EXPECT_GT(s.train_psnr, 0);
    EXPECT_GE(s.cg_iterations, 1);
    EXPECT_GT(s.seconds_total, 0);
    return ++calls < 3;
  }, &summary);
  EXPECT_EQ(calls, 3);
  EXPECT_EQ(summary.status, SolverStatus::kUserAbort);
  EXPECT_EQ(summary.iterations, 3);
  EXPECT_EQ(summary.linearize_passes, 3);
  // >= 2 trial points each (the subset's cost at x comes from the linearisation, not a pass),
  // and one pass for the final cost on all rays.
  EXPECT_GE(summary.cost_passes, 3 * 2 + 1);
  EXPECT_LE(summary.cost_passes, 3 * so.max_line_search_steps + 1);
  // initial_cost and final_cost are both the cost of all rays (not a rescaled subset).
  EXPECT_DOUBLE_EQ(summary.final_cost, backend->Cost(VectorsOf(so.type).params, Hash(so.seed, 2, 0)).cost);
  const std::string report = summary.BriefReport();
  EXPECT_NE(report.find("3 iterations"), std::string::npos) << report;
  EXPECT_NE(report.find("stopped by the caller"), std::string::npos) << report;
}

}  // namespace
}  // namespace perf::recon
