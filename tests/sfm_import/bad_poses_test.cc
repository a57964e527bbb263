// FindBadPoses (sfm_import/bad_poses.h): a pose far outside the cameras' spread that sees few
// points is found; far alone or weak alone is not; and the three wrong poses of shared/data/bonsai.
#include "sfm_import/bad_poses.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "tests/test_util.h"

namespace perf {
namespace {

// 20 cameras on a circle of radius 4 around the origin, looking at it, each seeing `points`
// of 100 shared points.
colmap::Reconstruction Circle() {
  colmap::Reconstruction rec;
  for (uint64_t p = 1; p <= 100; ++p) rec.points3D[p].point3D_id = p;
  for (uint32_t i = 1; i <= 20; ++i) {
    const double a = 2 * M_PI * i / 20;
    const Eigen::Vector3d centre(4 * std::cos(a), 4 * std::sin(a), 0.5);
    const Eigen::Matrix3d r_wc = Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Eigen::Quaterniond q(r_wc.transpose());  // cam_from_world
    const Eigen::Vector3d t = -(r_wc.transpose() * centre);
    colmap::Image& im = rec.images[i];
    im.image_id = i;
    im.name = "img" + std::to_string(i) + ".jpg";
    im.qvec = {q.w(), q.x(), q.y(), q.z()};
    im.tvec = {t.x(), t.y(), t.z()};
    for (uint64_t p = 1; p <= 80; ++p) im.points2D.push_back({0, 0, p});
    im.points2D.push_back({0, 0, colmap::kInvalidPoint3DId});  // not counted
  }
  return rec;
}

// Moves image i's centre to `centre` (keeping its rotation).
void MoveTo(colmap::Image* im, const Eigen::Vector3d& centre) {
  const Eigen::Quaterniond q(im->qvec[0], im->qvec[1], im->qvec[2], im->qvec[3]);
  const Eigen::Vector3d t = -(q.toRotationMatrix() * centre);
  im->tvec = {t.x(), t.y(), t.z()};
}

TEST(BadPoses, FarAndWeakIsFoundFarOrWeakAloneIsNot) {
  colmap::Reconstruction rec = Circle();
  EXPECT_TRUE(FindBadPoses(rec).empty());
  MoveTo(&rec.images[3], {18, 5, 0});  // far, all points: a wide shot, kept
  rec.images[7].points2D.resize(20);   // weak, in place: kept
  EXPECT_TRUE(FindBadPoses(rec).empty());
  rec.images[3].points2D.resize(30);   // far and weak
  const std::vector<BadPose> bad = FindBadPoses(rec);
  ASSERT_EQ(bad.size(), 1u);
  EXPECT_EQ(bad[0].name, "img3.jpg");
  EXPECT_NEAR(bad[0].median_distance, 4.0, 0.1);
  EXPECT_GT(bad[0].distance, 14.0);
  EXPECT_EQ(bad[0].points, 30);
  EXPECT_EQ(bad[0].median_points, 80);
  EXPECT_NE(bad[0].Describe().find("img3.jpg: "), std::string::npos) << bad[0].Describe();
  EXPECT_NE(bad[0].Describe().find("30 points (median 80)"), std::string::npos) << bad[0].Describe();
}

TEST(BadPoses, TheThreeWrongPosesOfBonsai) {
  PERF_REQUIRE_DATA(bonsai, "bonsai");
  const colmap::Reconstruction rec = colmap::ReadReconstruction(bonsai / "sparse" / "0");
  std::vector<std::string> names;
  for (const BadPose& b : FindBadPoses(rec)) {
    names.push_back(b.name);
    std::printf("%s\n", b.Describe().c_str());
  }
  EXPECT_EQ(names, (std::vector<std::string>{"DSCF5842.JPG", "DSCF5845.JPG", "DSCF5848.JPG"}));
}

}  // namespace
}  // namespace perf
