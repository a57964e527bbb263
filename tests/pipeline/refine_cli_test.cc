// `perf run --refine-poses on --refine-intrinsics focal` on the shipped example, as a user runs it
// (one small level): the refined cameras and focal lengths come back in scene.json, recon.json,
// report.json (the held-out views scored two ways) and WORKSPACE/sparse_refined, which perf import
// reads back; the example's own model is not touched; a later run without refinement drops them
// again.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "tests/test_util.h"
#include "workspace/scene.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

nlohmann::json ReadJson(const fs::path& path) { return nlohmann::json::parse(ReadFileToString(path)); }

TEST(RefineCli, RefinedCamerasComeBackEverywhere) {
  const fs::path example = fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini";
  const std::string model_before = ReadFileToString(example / "sparse" / "0" / "images.bin");
  test::TempDir dir;
  const fs::path ws = dir / "ws";
  const std::string source = " --colmap " + (example / "sparse" / "0").string() + " --images " +
                             (example / "images").string();
  const auto run = RunCommand(test::PerfBinary() + " run" + source + " --workspace " + ws.string() +
                              " --preset preview --max-size 96 --levels 1 --iterations 3 --refine-poses on"
                              " --refine-intrinsics focal --log-level quiet");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(ReadFileToString(example / "sparse" / "0" / "images.bin"), model_before);

  const Scene scene = ReadScene(ws / "scene.json");
  int train = 0, refined = 0, focal = 0;
  for (const SceneImage& im : scene.images) {
    train += im.split == Split::kTrain;
    refined += im.refined_world_from_cam.has_value();
    focal += im.refined_focal_scale.has_value() && *im.refined_focal_scale != 1.0;
  }
  EXPECT_EQ(refined, static_cast<int>(scene.images.size()));  // the held-out ones from their neighbours
  EXPECT_EQ(focal, static_cast<int>(scene.images.size()));
  const nlohmann::json recon = ReadJson(ws / "recon" / "recon.json");
  EXPECT_EQ(recon["poses"]["photos"], train);
  EXPECT_TRUE(recon["poses"]["corrections"]["refined"].get<bool>());
  EXPECT_TRUE(recon["poses"]["focal"].get<bool>());
  EXPECT_GT(recon["poses"]["corrections"]["max_focal_change"].get<double>(), 0.0);
  EXPECT_EQ(recon["poses"]["corrections"]["photos"].size(), static_cast<size_t>(train));
  const nlohmann::json report = ReadJson(ws / "report.json");
  EXPECT_GT(report["held_out_cameras"]["pose_fit"]["mean_psnr"].get<double>(), 10.0) << report.dump(1);
  for (const auto& v : report["test_views"]) EXPECT_TRUE(v.contains("psnr_pose_fit")) << v.dump();
  const nlohmann::json manifest = ReadJson(ws / "export.json");
  EXPECT_EQ(manifest["refined_model"]["dir"], "sparse_refined");
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) EXPECT_TRUE(fs::exists(ws / "sparse_refined" / f));

  // perf import reads the refined model back, with the refined poses.
  const fs::path again = dir / "again";
  const auto import = RunCommand(test::PerfBinary() + " import -q --colmap " + (ws / "sparse_refined").string() +
                                 " --images " + (example / "images").string() + " -w " + again.string());
  ASSERT_EQ(import.exit_code, 0) << import.output;
  const Scene back = ReadScene(again / "scene.json");
  int compared = 0;
  const SceneImage* first = nullptr;  // focal lengths compared as ratios (the import's own downscale)
  double first_scale = 1;
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kExcluded) continue;
    for (const SceneImage& b : back.images) {
      if (b.name != im.name) continue;
      EXPECT_LT((b.world_from_cam - *im.refined_world_from_cam).norm(), 1e-9) << im.name;
      if (!first) {
        first = &b;
        first_scale = *im.refined_focal_scale;
      }
      const double want = *im.refined_focal_scale / first_scale;
      // The model's distortion is undistorted again on import: the scale holds to first order.
      EXPECT_NEAR(back.camera(b.camera_id).fx / back.camera(first->camera_id).fx, want, 1e-3) << im.name;
      ++compared;
    }
  }
  EXPECT_GT(compared, train);

  // Without refinement the refined poses and the refined model go.
  const auto plain = RunCommand(test::PerfBinary() + " reconstruct " + ws.string() +
                                " --levels 1 --iterations 1 --refine-poses off -q");
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  for (const SceneImage& im : ReadScene(ws / "scene.json").images) {
    EXPECT_FALSE(im.refined_world_from_cam) << im.name;
    EXPECT_FALSE(im.refined_focal_scale) << im.name;
  }
  const auto exported = RunCommand(test::PerfBinary() + " export " + ws.string() +
                                   " --no-masks --no-foreground --no-volume --no-mesh --no-renders -q");
  ASSERT_EQ(exported.exit_code, 0) << exported.output;
  EXPECT_FALSE(fs::exists(ws / "sparse_refined"));
}

// The focal length is refined with the poses only: asked for with the poses off, perf says what to
// change, before it imports anything.
TEST(RefineCli, FocalWithoutPosesIsRefused) {
  const fs::path example = fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini";
  test::TempDir dir;
  const auto run = RunCommand(test::PerfBinary() + " run --colmap " + (example / "sparse" / "0").string() +
                              " --images " + (example / "images").string() + " --workspace " + (dir / "ws").string() +
                              " --refine-poses off --refine-intrinsics focal");
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.output.find("--refine-intrinsics"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("--refine-poses on"), std::string::npos) << run.output;
  EXPECT_FALSE(fs::exists(dir / "ws" / "scene.json"));
}

}  // namespace
}  // namespace perf
