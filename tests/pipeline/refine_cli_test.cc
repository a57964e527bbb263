// `perf run --refine-poses on` on the shipped example, as a user runs it (one small level): the
// refined cameras come back in scene.json, recon.json, report.json (the held-out views scored two
// ways) and WORKSPACE/sparse_refined, which perf import reads back; the example's own model is not
// touched; a later run without refinement drops them again.
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
                              " --preset preview --max-size 96 --levels 1 --iterations 3 --refine-poses on --log-level quiet");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(ReadFileToString(example / "sparse" / "0" / "images.bin"), model_before);

  const Scene scene = ReadScene(ws / "scene.json");
  int train = 0, refined = 0;
  for (const SceneImage& im : scene.images) {
    train += im.split == Split::kTrain;
    refined += im.refined_world_from_cam.has_value();
  }
  EXPECT_EQ(refined, static_cast<int>(scene.images.size()));  // the held-out ones from their neighbours
  const nlohmann::json recon = ReadJson(ws / "recon" / "recon.json");
  EXPECT_EQ(recon["poses"]["photos"], train);
  EXPECT_TRUE(recon["poses"]["corrections"]["refined"].get<bool>());
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
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kExcluded) continue;
    for (const SceneImage& b : back.images) {
      if (b.name != im.name) continue;
      EXPECT_LT((b.world_from_cam - *im.refined_world_from_cam).norm(), 1e-9) << im.name;
      ++compared;
    }
  }
  EXPECT_GT(compared, train);

  // Without refinement the refined poses and the refined model go.
  const auto plain = RunCommand(test::PerfBinary() + " reconstruct " + ws.string() +
                                " --levels 1 --iterations 1 --refine-poses off -q");
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  for (const SceneImage& im : ReadScene(ws / "scene.json").images) EXPECT_FALSE(im.refined_world_from_cam) << im.name;
  const auto exported = RunCommand(test::PerfBinary() + " export " + ws.string() +
                                   " --no-masks --no-foreground --no-volume --no-mesh --no-renders -q");
  ASSERT_EQ(exported.exit_code, 0) << exported.output;
  EXPECT_FALSE(fs::exists(ws / "sparse_refined"));
}

}  // namespace
}  // namespace perf
