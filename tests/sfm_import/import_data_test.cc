// Imports of the real data sets in ../shared/data (skipped when absent).
#include <gtest/gtest.h>

#include <algorithm>

#include "sfm_import/box_preview.h"
#include "workspace/image_io.h"
#include "sfm_import/importer.h"
#include "tests/test_util.h"

namespace perf {
namespace {

double Cross(const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
}

// Convex hull, counter-clockwise (Andrew's monotone chain).
std::vector<Eigen::Vector2d> Hull(std::vector<Eigen::Vector2d> p) {
  std::sort(p.begin(), p.end(), [](const auto& a, const auto& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
  std::vector<Eigen::Vector2d> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && Cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && Cross(h[k - 2], h[k - 1], p[i - 1]) <= 0) --k;
    h[k++] = p[i - 1];
  }
  h.resize(k - 1);
  return h;
}

bool InHull(const std::vector<Eigen::Vector2d>& h, const Eigen::Vector2d& q) {
  for (size_t i = 0; i < h.size(); ++i) {
    if (Cross(h[i], h[(i + 1) % h.size()], q) < 0) return false;
  }
  return true;
}

TEST(ImportData, LegoBoxHoldsEveryForegroundPixel) {
  PERF_REQUIRE_DATA(lego, "lego");
  test::TempDir dir;
  ImportOptions o;
  o.nerf_json = lego / "transforms_train.json";
  o.workspace = dir / "ws";
  o.downscale = 8;
  const ImportResult r = RunImport(o);
  const Scene& s = r.scene;
  ASSERT_EQ(s.images.size(), 100u);
  EXPECT_EQ(s.cameras[0].width, 100);
  // Every 8th view in json order is held out: r_0, r_8, ..., r_96.
  int test = 0;
  for (size_t i = 0; i < s.images.size(); ++i) {
    EXPECT_EQ(s.images[i].name, "train/r_" + std::to_string(i) + ".png");
    EXPECT_EQ(s.images[i].split == Split::kTest, i % 8 == 0);
    test += s.images[i].split == Split::kTest;
  }
  EXPECT_EQ(test, 13);
  // The object (alpha > 0.5) lies inside the projected box in every view: the box contains it.
  long outside = 0, foreground = 0;
  for (size_t i = 0; i < s.images.size(); ++i) {
    const auto corners = ProjectBoxCorners(s, i);
    for (const auto& c : corners) ASSERT_TRUE(c.allFinite()) << "box corner behind camera " << i;
    const auto hull = Hull(corners);
    const Image alpha = ReadImage(o.workspace / s.images[i].alpha_path);
    for (int y = 0; y < alpha.height; ++y)
      for (int x = 0; x < alpha.width; ++x) {
        if (alpha.at(x, y, 0) <= 0.5f) continue;
        ++foreground;
        outside += InHull(hull, {x + 0.5, y + 0.5}) ? 0 : 1;
      }
  }
  EXPECT_GT(foreground, 100 * 1000);
  EXPECT_EQ(outside, 0);
  // And it is not absurdly loose: the lego fits in about [-0.7, 0.7] x [-1.2, 1.2] x [-0.4, 1.1].
  EXPECT_LT(s.box.size.maxCoeff(), 4.0);
}

TEST(ImportData, BonsaiImportsWithUndistortion) {
  PERF_REQUIRE_DATA(bonsai, "bonsai");
  test::TempDir dir;
  ImportOptions o;
  o.colmap_dir = bonsai / "sparse" / "0";
  o.images_dir = bonsai / "images";
  o.workspace = dir / "ws";
  o.downscale = 4;
  const ImportResult r = RunImport(o);
  const Scene& s = r.scene;
  ASSERT_EQ(s.images.size(), 84u);
  ASSERT_EQ(s.cameras.size(), 1u);
  EXPECT_EQ(s.cameras[0].source.model, "OPENCV");
  EXPECT_EQ(s.cameras[0].width, 200);
  EXPECT_EQ(s.cameras[0].height, 133);
  EXPECT_TRUE(r.bounds.object_centric);  // a 360-degree capture
  // The box surrounds the point all cameras look at, and sits well inside the camera ring.
  const Eigen::Vector3d local = s.box.rotation.transpose() * (r.bounds.axes_point - s.box.center);
  EXPECT_TRUE((local.cwiseAbs().array() <= 0.5 * s.box.size.array()).all());
  double nearest = 1e300;
  for (const auto& im : s.images) nearest = std::min(nearest, (im.world_from_cam.col(3) - s.box.center).norm());
  EXPECT_LT(0.5 * s.box.size.maxCoeff(), nearest);
  EXPECT_GT(r.bounds.num_points_used, 1000);
  EXPECT_EQ(ReadImageInfo(o.workspace / s.images[0].path).width, 200);
  // The five wrong poses (bad_poses.h) are named.
  int wrong = 0;
  for (const std::string& w : r.warnings) wrong += w.find("looks wrong") != std::string::npos;
  EXPECT_EQ(wrong, 5);
  EXPECT_NE(ImportSummary(r).find("the pose of DSCF5644.JPG looks wrong ("), std::string::npos) << ImportSummary(r);
  EXPECT_NE(ImportSummary(r).find("the pose of DSCF5848.JPG looks wrong ("), std::string::npos) << ImportSummary(r);
  // The start of the capture sees a second bonsai (ghost_groups.h): two groups are named, each
  // with all of its photos, and none of the 60 photos from DSCF5668 on.
  std::vector<std::string> ghosts;
  for (const std::string& w : r.warnings) {
    if (w.find("COLMAP reconstructed the object twice") != std::string::npos) ghosts.push_back(w);
  }
  ASSERT_EQ(ghosts.size(), 2u) << ImportSummary(r);
  EXPECT_EQ(ghosts[0].rfind("11 photos (DSCF5605.JPG ... DSCF5635.JPG) see ", 0), 0u) << ghosts[0];
  EXPECT_NE(ghosts[0].find("the other 60 photos see, and share none"), std::string::npos) << ghosts[0];
  EXPECT_NE(ghosts[0].find("DSCF5620.JPG, DSCF5623.JPG"), std::string::npos) << ghosts[0];
  EXPECT_EQ(ghosts[1].rfind("5 photos (DSCF5638.JPG ... DSCF5659.JPG) see ", 0), 0u) << ghosts[1];
  for (const std::string& w : ghosts) EXPECT_EQ(w.find("DSCF5668"), std::string::npos) << w;
  // scene.json says so for each of their photos (perf eval's report repeats it for held-out ones).
  int doubted = 0;
  for (const auto& im : s.images) {
    doubted += !im.pose_doubt.empty();
    if (im.name == "DSCF5605.JPG" || im.name == "DSCF5659.JPG") EXPECT_FALSE(im.pose_doubt.empty()) << im.name;
    if (im.name == "DSCF5668.JPG") EXPECT_TRUE(im.pose_doubt.empty()) << im.pose_doubt;
  }
  EXPECT_EQ(doubted, 16);
  // They are named, not left out: 84 photos less the five wrong poses train or are held out.
  int left_out = 0;
  for (const auto& im : s.images) left_out += im.split == Split::kExcluded;
  EXPECT_EQ(left_out, 5);
}

}  // namespace
}  // namespace perf
