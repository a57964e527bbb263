// The real data: lego (NeRF synthetic) imported at 50 x 50 and reconstructed with the default
// solver on the CPU, 32^3 then 64^3, 8 Gauss-Newton iterations each (CALIBRATION.md's setting),
// then exported and evaluated against the photos' alpha (the true foreground).
// About 50 s on 2 cores, so it runs in the default suite as the quality gate of the solver;
// skips without ../shared/data.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <tuple>

#include "export/evaluate.h"
#include "export/export.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/box_check.h"
#include "recon_cuda/run/reconstruct.h"
#include "sfm_import/importer.h"
#include "tests/test_util.h"

namespace perf::recon {
namespace {

namespace fs = std::filesystem;

// Lego imported at 50 x 50 (downscale 16) into `workspace`, and a CPU reconstruction of it.
ImportOptions LegoImport(const fs::path& workspace) {
  ImportOptions io;
  io.nerf_json = test::SharedData("lego") / "transforms_train.json";
  io.workspace = workspace;
  io.downscale = 16;
  return io;
}
ReconstructOptions CpuReconstruct(const fs::path& workspace, int levels, int iterations) {
  ReconstructOptions o;
  o.workspace = workspace;
  o.device = DeviceChoice::kCpu;
  o.levels = levels;
  o.iterations = iterations;
  o.solver.cost_tolerance = 0;  // every iteration, as calibrated
  return o;
}

class LegoTest : public ::testing::Test {
 protected:
  // One reconstruction for both tests.
  static void SetUpTestSuite() {
    const fs::path lego = test::SharedData("lego");
    if (lego.empty()) return;
    dir_ = new test::TempDir();
    RunImport(LegoImport(*dir_ / "ws"));
    result_ = new ReconstructResult(Reconstruct(CpuReconstruct(*dir_ / "ws", 2, 8)));
  }
  static void TearDownTestSuite() {
    delete result_;
    delete dir_;
    result_ = nullptr;
    dir_ = nullptr;
  }
  void SetUp() override {
    PERF_REQUIRE_DATA(lego, "lego");
    ASSERT_NE(result_, nullptr);
  }
  static fs::path Workspace() { return *dir_ / "ws"; }
  static test::TempDir* dir_;
  static ReconstructResult* result_;
};
test::TempDir* LegoTest::dir_ = nullptr;
ReconstructResult* LegoTest::result_ = nullptr;

TEST_F(LegoTest, HeldOutPsnrAt50Pixels) {
  const ReconstructResult& r = *result_;
  ASSERT_EQ(r.levels.size(), 2u);
  std::printf("lego 50x50, 8 + 8 GN iterations: held-out PSNR %.2f dB in %.1f s (%s)\n", r.test_psnr,
              r.solve_seconds, r.backend.c_str());
  // Measured 28.36 dB with a dense level 1, 28.30 sparse (fixed white background, projected GN,
  // centred rays, opacity fitted to the alpha with weight 0.3, 6 CG iterations, scored without the
  // paper's render rule; 22.98 dB before those). CALIBRATION.md's minimal implementation reached 26.6 dB in this setting, and
  // the bar stays above it. It leaves 1 dB for float summation order across thread counts and
  // machines. Level 1 must improve on level 0.
  EXPECT_TRUE(r.fixed_background);
  EXPECT_GT(r.test_psnr, 27.36);
  EXPECT_GT(r.levels[1].test_psnr, r.levels[0].test_psnr + 0.5);
  EXPECT_GT(r.levels[1].train_psnr, 20.0);
}

TEST_F(LegoTest, ExportAndMasksAgainstAlpha) {
  exporter::ExportOptions eo;
  eo.workspace = Workspace();
  eo.device = DeviceChoice::kCpu;
  eo.orbit.frames = 4;
  const exporter::ExportResult x = exporter::RunExport(eo);
  EXPECT_EQ(x.masks, 100);  // every photo, train and held out
  EXPECT_GT(x.vdb.active_voxels, 0);
  EXPECT_GT(x.mesh_triangles, 1000);
  exporter::EvalOptions vo;
  vo.workspace = Workspace();
  vo.device = DeviceChoice::kCpu;
  const exporter::EvalResult e = exporter::RunEval(vo);
  std::printf("lego 50x50: held-out PSNR %.2f dB, SSIM %.3f; masks vs alpha: IoU %.3f, precision %.3f, recall %.3f; "
              "vdb %lld voxels, %lld KiB; mesh %lld triangles at iso %.2f, silhouette IoU %.3f\n",
              e.mean.psnr, e.mean.ssim, e.pooled.iou, e.pooled.precision, e.pooled.recall,
              static_cast<long long>(x.vdb.active_voxels), static_cast<long long>(x.vdb.file_bytes / 1024),
              static_cast<long long>(x.mesh_triangles), x.iso.iso, x.iso.silhouette_iou);
  EXPECT_EQ(e.mask_truth, "alpha");
  ASSERT_EQ(e.masks.size(), 100u);
  // Measured IoU 0.962 (precision 0.987, recall 0.975). The opacity residual fits the box
  // opacity to the photos' alpha; without it white fog outside the object, invisible against
  // the white background, filled the masks (IoU 0.40); with its weight at 0.1 the IoU was 0.930.
  // The bars leave about 0.03 for machines and thread counts; the masks are rendered at 50x50
  // and mapped up to 800x800, so their edges are soft.
  EXPECT_GT(e.pooled.recall, 0.94);
  EXPECT_GT(e.pooled.precision, 0.95);
  EXPECT_GT(e.pooled.iou, 0.93);
  EXPECT_GT(e.mean.ssim, 0.95);  // measured 0.965
  EXPECT_NEAR(e.mean.psnr, result_->test_psnr, 0.05) << "eval and reconstruct score the same renders";
}

// The box check of issue 16 acting: lego imported with a box too small for it (1.5 units a side
// where the object spans about 1.3 x 2.4 x 1.5) makes the first level's density reach the side
// faces; perf reconstruct grows the box there, writes it to scene.json and fits the level again,
// which scores better than the fit in the box as imported (--no-grow-box).
TEST(LegoBox, ABoxTooSmallGrowsWhereTheObjectGoesOn) {
  PERF_REQUIRE_DATA(lego, "lego");
  test::TempDir dir;
  const auto fit = [&](const std::string& name, bool grow) {
    ImportOptions io = LegoImport(dir.path() / name);
    io.box_size = Eigen::Vector3d(1.5, 1.5, 1.5);
    RunImport(io);
    ReconstructOptions o = CpuReconstruct(io.workspace, 1, 8);
    o.grow_box = grow;
    std::vector<std::string> said;
    o.on_event = [&](const ReconstructOptions::Event& e) {
      if (!e.message.empty()) said.push_back(e.message);
    };
    const ReconstructResult r = Reconstruct(o);
    const Scene scene = ReadScene(io.workspace / "scene.json");
    std::ifstream in(io.workspace / "recon" / "recon.json");
    const nlohmann::json recon = nlohmann::json::parse(in);
    return std::make_tuple(r, scene, recon, said);
  };
  const auto [kept, kept_scene, kept_json, kept_said] = fit("kept", false);
  const auto [grown, grown_scene, grown_json, grown_said] = fit("grown", true);

  EXPECT_TRUE(kept_json["box_growths"].empty());
  EXPECT_FALSE(kept_json["box_warning"].get<std::string>().empty());
  EXPECT_EQ(kept_scene.box.size, Eigen::Vector3d(1.5, 1.5, 1.5));

  ASSERT_FALSE(grown_json["box_growths"].empty()) << grown_json.dump(1);
  EXPECT_LE(grown_json["box_growths"].size(), static_cast<size_t>(kMaxBoxGrowths));
  // scene.json holds the grown box, larger than imported and never smaller along any axis.
  EXPECT_GT(grown_scene.box.size.prod(), 1.5 * 1.5 * 1.5 * 1.2);
  for (int a = 0; a < 3; ++a) EXPECT_GE(grown_scene.box.size[a], 1.5);
  EXPECT_NE(grown_scene.box.method.find("grown by perf reconstruct"), std::string::npos);
  // The checkpoint was fitted in it, and the run said so.
  const Checkpoint c = ReadCheckpoint(CheckpointPath(dir.path() / "grown", 0));
  for (int a = 0; a < 3; ++a) EXPECT_DOUBLE_EQ(c.placement.box_size[a], grown_scene.box.size[a]);
  EXPECT_TRUE(std::any_of(grown_said.begin(), grown_said.end(), [](const std::string& m) {
    return m.find("the box grows 25 % there") != std::string::npos;
  }));
  ASSERT_EQ(grown.levels.size(), 1u);  // the discarded fits are not reported as levels
  std::printf("lego 50x50 in a 1.5^3 box, 32^3 x 8: held-out %.2f dB kept, %.2f dB grown %zu times to %.2f x %.2f x %.2f\n",
              kept.test_psnr, grown.test_psnr, grown_json["box_growths"].size(), grown_scene.box.size[0],
              grown_scene.box.size[1], grown_scene.box.size[2]);
  EXPECT_GT(grown.test_psnr, kept.test_psnr + 0.5);
}

}  // namespace
}  // namespace perf::recon
