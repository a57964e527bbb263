// FindGhostGroups (sfm_import/ghost_groups.h): a group of photos that sees its own copy of the
// object, far from where the others see it and sharing none of its points, is named; the far side
// of one object seen by photos that share nothing with the front is not, nor a group that shares a
// point, a group too small, or photos left out for a wrong pose. shared/data/bonsai's groups are
// asserted in import_data_test.
#include "sfm_import/ghost_groups.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace perf {
namespace {

// Only what FindGhostGroups reads: names, which points each photo sees, the points' positions.
// `photos` photos img01 ... imgNN, seeing no points until Cluster() adds them.
colmap::Reconstruction Photos(int photos) {
  colmap::Reconstruction rec;
  for (uint32_t i = 1; i <= static_cast<uint32_t>(photos); ++i) {
    rec.images[i].image_id = i;
    rec.images[i].name = "img" + std::string(i < 10 ? "0" : "") + std::to_string(i) + ".jpg";
  }
  return rec;
}

// Adds `count` points, ids from `first`, spread over a ball of radius `radius` around `centre`
// (a deterministic spiral), each seen by the photos `from` ... `to` (a sliding window of three
// photos, so that consecutive photos share points and the set is one group).
void Cluster(colmap::Reconstruction* rec, uint64_t first, int count, const Eigen::Vector3d& centre, double radius,
             uint32_t from, uint32_t to) {
  for (int k = 0; k < count; ++k) {
    const double t = (k + 0.5) / count, a = 2.4 * k;
    const Eigen::Vector3d p = centre + radius * std::cbrt(t) *
                                           Eigen::Vector3d(std::sqrt(1 - (2 * t - 1) * (2 * t - 1)) * std::cos(a),
                                                           std::sqrt(1 - (2 * t - 1) * (2 * t - 1)) * std::sin(a),
                                                           2 * t - 1);
    colmap::Point3D& pt = rec->points3D[first + k];
    pt.point3D_id = first + k;
    pt.xyz = {p.x(), p.y(), p.z()};
    const uint32_t n = to - from + 1, start = from + static_cast<uint32_t>(k) % n;
    for (uint32_t j = 0; j < 3 && j < n; ++j) {
      const uint32_t photo = from + (start - from + j) % n;
      rec->images[photo].points2D.push_back({0, 0, first + k});
    }
  }
}

SceneBox Box(double side) {
  SceneBox box;
  box.size = Eigen::Vector3d::Constant(side);
  return box;
}

TEST(GhostGroups, AGroupSeeingItsOwnObjectFarAwayIsNamed) {
  colmap::Reconstruction rec = Photos(20);
  Cluster(&rec, 1, 300, Eigen::Vector3d::Zero(), 0.8, 1, 14);     // the object, photos 1-14
  Cluster(&rec, 1001, 60, Eigen::Vector3d(2.5, 0, 0), 0.4, 15, 20);  // a second copy, photos 15-20
  Cluster(&rec, 2001, 100, Eigen::Vector3d(20, 0, 0), 1, 1, 20);      // the room, outside the box: shared
  rec.images[15].points2D.push_back({0, 0, colmap::kInvalidPoint3DId});  // not a point: ignored
  const std::vector<GhostGroup> ghosts = FindGhostGroups(rec, Box(8), {});
  ASSERT_EQ(ghosts.size(), 1u);
  const GhostGroup& g = ghosts[0];
  ASSERT_EQ(g.names.size(), 6u);
  EXPECT_EQ(g.names.front(), "img15.jpg");
  EXPECT_EQ(g.names.back(), "img20.jpg");
  EXPECT_EQ(g.points, 60);
  EXPECT_EQ(g.main_photos, 14);
  EXPECT_EQ(g.main_points, 300);
  EXPECT_NEAR(g.separation, 2.5, 0.05);
  EXPECT_NEAR(g.main_radius, 0.8 * std::sqrt(3.0 / 5.0), 0.08);  // RMS radius of a uniform ball
  EXPECT_EQ(g.Describe().rfind("6 photos (img15.jpg ... img20.jpg) see 60 sparse points inside the box 2.5 units", 0),
            0u)
      << g.Describe();
  EXPECT_NE(g.Warning().find("The photos: img15.jpg, img16.jpg, img17.jpg, img18.jpg, img19.jpg, img20.jpg"),
            std::string::npos)
      << g.Warning();
  // With the room inside the box the room's shared points join everyone: one group, none named.
  EXPECT_TRUE(FindGhostGroups(rec, Box(60), {}).empty());
}

TEST(GhostGroups, MarkingPutsTheDoubtOnTheGroupsPhotosInTheScene) {
  colmap::Reconstruction rec = Photos(20);
  Cluster(&rec, 1, 300, Eigen::Vector3d::Zero(), 0.8, 1, 14);
  Cluster(&rec, 1001, 60, Eigen::Vector3d(2.5, 0, 0), 0.4, 15, 20);
  Scene scene;
  scene.box = Box(8);
  for (const auto& [id, im] : rec.images) scene.images.push_back({.name = im.name});
  const std::vector<std::string> warnings = MarkGhostGroups(rec, {}, &scene);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("COLMAP reconstructed the object twice"), std::string::npos) << warnings[0];
  for (const SceneImage& im : scene.images) {
    const bool in_group = im.name >= "img15.jpg";
    EXPECT_EQ(im.pose_doubt.empty(), !in_group) << im.name << ": " << im.pose_doubt;
    if (in_group) EXPECT_EQ(im.pose_doubt.rfind("in a group that sees the object elsewhere: 6 photos", 0), 0u);
  }
}

TEST(GhostGroups, TheFarSideOfOneObjectIsNotAGhost) {
  colmap::Reconstruction rec = Photos(20);
  Cluster(&rec, 1, 300, Eigen::Vector3d(-0.4, 0, 0), 0.6, 1, 10);  // the front half
  Cluster(&rec, 1001, 300, Eigen::Vector3d(0.4, 0, 0), 0.6, 11, 20);  // the back half: no shared point
  EXPECT_TRUE(FindGhostGroups(rec, Box(8), {}).empty());
  // The same halves 3 units apart are two objects: the second group is named.
  for (uint64_t id = 1001; id < 1301; ++id) rec.points3D[id].xyz[0] += 2.6;
  EXPECT_EQ(FindGhostGroups(rec, Box(8), {}).size(), 1u);
}

TEST(GhostGroups, ASharedPointASmallGroupOrLeftOutPhotosNameNone) {
  colmap::Reconstruction rec = Photos(20);
  Cluster(&rec, 1, 300, Eigen::Vector3d::Zero(), 0.8, 1, 14);
  Cluster(&rec, 1001, 60, Eigen::Vector3d(2.5, 0, 0), 0.4, 15, 20);
  ASSERT_EQ(FindGhostGroups(rec, Box(8), {}).size(), 1u);

  colmap::Reconstruction shared = rec;  // one point of the object also seen by photo 17
  shared.images[17].points2D.push_back({0, 0, 1});
  EXPECT_TRUE(FindGhostGroups(shared, Box(8), {}).empty());
  GhostGroupOptions two;  // ... unless a link needs two shared points
  two.min_shared_points = 2;
  EXPECT_EQ(FindGhostGroups(shared, Box(8), {}, two).size(), 1u);

  std::map<std::string, std::string> left_out;  // four of the six left out: two remain, too few
  for (int i = 15; i <= 18; ++i) left_out["img" + std::to_string(i) + ".jpg"] = "pose looks wrong";
  EXPECT_TRUE(FindGhostGroups(rec, Box(8), left_out).empty());

  GhostGroupOptions many;  // 60 points, fewer than asked for
  many.min_points = 61;
  EXPECT_TRUE(FindGhostGroups(rec, Box(8), {}, many).empty());

  EXPECT_TRUE(FindGhostGroups(Photos(5), Box(8), {}).empty());  // no points at all
}

}  // namespace
}  // namespace perf
