// WORKSPACE/sparse_refined (refined_model.h) from the example's real COLMAP model: the refined
// images' poses replace the imported ones, the rest of the model is kept, the imported model is
// not touched, PERF's reader reads it back, and so does `colmap model_analyzer` where COLMAP is
// installed.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstdlib>
#include <fstream>

#include "common/atomic_file.h"
#include "export/refined_model.h"
#include "sfm_import/colmap_model.h"
#include "sfm_import/colmap_pose.h"
#include "tests/test_util.h"

namespace perf::exporter {
namespace {

namespace fs = std::filesystem;

// A scene of the model's images as perf import keeps them: every third held out, one excluded;
// each image refined by a small turn and shift of its own, every fourth its focal length too.
Scene SceneOf(const fs::path& model, const colmap::Reconstruction& rec) {
  Scene s;
  s.source.type = "colmap";
  s.source.path = model.string();
  int k = 0;
  for (const auto& [id, im] : rec.images) {
    SceneImage si;
    si.name = im.name;
    si.world_from_cam = WorldFromCam(im);
    si.split = k == 5 ? Split::kExcluded : k % 3 == 0 ? Split::kTest : Split::kTrain;
    Eigen::Matrix<double, 3, 4> refined = si.world_from_cam;
    refined.leftCols<3>() = Eigen::AngleAxisd(0.002 * (k + 1), Eigen::Vector3d(1, 2, 3).normalized()) *
                            si.world_from_cam.leftCols<3>();
    refined.col(3) += Eigen::Vector3d(0.01 * k, -0.005, 0.002 * k);
    si.refined_world_from_cam = refined;
    if (k % 4 == 1) si.refined_focal_scale = 1.0 + 0.001 * k;
    s.images.push_back(si);
    ++k;
  }
  return s;
}

TEST(RefinedModel, CarriesTheRefinedPosesAndKeepsTheRest) {
  test::TempDir dir;
  const fs::path imported = dir.path() / "imported";
  fs::create_directories(imported);
  const fs::path example = fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini" / "sparse" / "0";
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) fs::copy_file(example / f, imported / f);
  const std::string images_before = ReadFileToString(imported / "images.bin");
  const colmap::Reconstruction rec = colmap::ReadReconstruction(imported);
  ASSERT_GT(rec.images.size(), 6u);
  const Scene scene = SceneOf(imported, rec);

  const fs::path ws = dir.path() / "ws";
  fs::create_directories(ws);
  const RefinedModel r = WriteRefinedModel(scene, ws);
  EXPECT_EQ(r.dir, fs::path("sparse_refined"));
  EXPECT_EQ(r.moved, static_cast<int>(rec.images.size()) - 1);  // all but the excluded one
  EXPECT_EQ(ReadFileToString(imported / "images.bin"), images_before);  // the user's model untouched

  const colmap::Reconstruction back = colmap::ReadReconstruction(ws / "sparse_refined");
  ASSERT_EQ(back.images.size(), rec.images.size());
  EXPECT_EQ(back.points3D.size(), rec.points3D.size());
  // A photo with a refined focal length gets its own camera, the imported one's with f scaled.
  size_t focal = 0;
  for (const SceneImage& si : scene.images) focal += si.refined_focal_scale && si.split != Split::kExcluded;
  ASSERT_GT(focal, 0u);
  EXPECT_EQ(back.cameras.size(), rec.cameras.size() + focal);
  for (const SceneImage& si : scene.images) {
    const colmap::Image* im = nullptr;
    for (const auto& [id, b] : back.images) im = b.name == si.name ? &b : im;
    ASSERT_NE(im, nullptr) << si.name;
    const Eigen::Matrix<double, 3, 4> want = si.split == Split::kExcluded ? si.world_from_cam : *si.refined_world_from_cam;
    EXPECT_LT((WorldFromCam(*im) - want).norm(), 1e-9) << si.name;
    EXPECT_EQ(im->points2D.size(), rec.images.at(im->image_id).points2D.size());
    const colmap::Camera& was = rec.cameras.at(rec.images.at(im->image_id).camera_id);
    const colmap::Camera& now = back.cameras.at(im->camera_id);
    const double scale = si.refined_focal_scale && si.split != Split::kExcluded ? *si.refined_focal_scale : 1.0;
    EXPECT_EQ(im->camera_id != was.camera_id, scale != 1.0) << si.name;
    EXPECT_NEAR(now.params[0], was.params[0] * scale, 1e-9) << si.name;
    EXPECT_EQ(now.params.back(), was.params.back()) << si.name;  // the rest kept
  }
  // A model from another source is not written, and says why.
  Scene nerf = scene;
  nerf.source.type = "nerf";
  EXPECT_FALSE(WriteRefinedModel(nerf, dir.path() / "ws2").not_written.empty());
  EXPECT_FALSE(fs::exists(dir.path() / "ws2" / "sparse_refined"));

  if (std::system("command -v colmap > /dev/null 2>&1") != 0) GTEST_SKIP() << "colmap is not installed";
  const std::string log = (dir.path() / "analyzer.txt").string();
  const std::string command = "colmap model_analyzer --path " + (ws / "sparse_refined").string() + " > " + log + " 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << ReadFileToString(log);
  const std::string said = ReadFileToString(log);
  EXPECT_NE(said.find("Registered images: " + std::to_string(rec.images.size())), std::string::npos) << said;
}

}  // namespace
}  // namespace perf::exporter
