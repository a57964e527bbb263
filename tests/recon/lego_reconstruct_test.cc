// The real data: lego (NeRF synthetic) imported at 50 x 50 and reconstructed with the default
// solver on the CPU, 32^3 then 64^3, 8 Gauss-Newton iterations each (CALIBRATION.md's setting).
// Label `slow` (about a minute on 2 cores); skips without ../shared/data.
#include <gtest/gtest.h>

#include <cstdio>

#include "recon_cuda/reconstruct.h"
#include "sfm_import/importer.h"
#include "tests/test_util.h"

namespace perf::recon {
namespace {

TEST(LegoReconstructTest, HeldOutPsnrAt50Pixels) {
  PERF_REQUIRE_DATA(lego, "lego");
  test::TempDir dir;
  ImportOptions io;
  io.nerf_json = lego / "transforms_train.json";
  io.workspace = dir / "ws";
  io.downscale = 16;
  RunImport(io);
  ReconstructOptions o;
  o.workspace = io.workspace;
  o.device = "cpu";
  o.levels = 2;
  o.iterations = 8;
  const ReconstructResult r = Reconstruct(o);
  ASSERT_EQ(r.levels.size(), 2u);
  std::printf("lego 50x50, 8 + 8 GN iterations: held-out PSNR %.2f dB in %.1f s (%s)\n", r.test_psnr,
              r.solve_seconds, r.backend.c_str());
  // Measured 22.7 dB (closing note of issue 3); the bar leaves 1.2 dB for float summation order
  // across thread counts and machines. Level 1 must improve on level 0.
  EXPECT_GT(r.test_psnr, 21.5);
  EXPECT_GT(r.levels[1].test_psnr, r.levels[0].test_psnr + 0.5);
  EXPECT_GT(r.levels[1].train_psnr, 20.0);
}

}  // namespace
}  // namespace perf::recon
