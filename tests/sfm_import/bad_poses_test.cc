// FindBadPoses (sfm_import/bad_poses.h): a pose far outside the cameras' spread that sees few
// points is found; far alone or weak alone is not; a far pose turned away from what the others look
// at is found; and the five wrong poses of shared/data/bonsai.
#include "sfm_import/bad_poses.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "sfm_import/camera_models.h"
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

// Puts image `im` at `centre` looking at `target`, world z up (camera x right, y down).
void LookFrom(colmap::Image* im, const Eigen::Vector3d& centre, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  Eigen::Matrix3d r_wc;
  r_wc << x, z.cross(x), z;
  const Eigen::Quaterniond q(r_wc.transpose());
  im->qvec = {q.w(), q.x(), q.y(), q.z()};
  MoveTo(im, centre);
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

// 20 pinhole cameras (800 x 600, f 600) on a circle of radius 4 at height 1, each looking at
// the origin and seeing 80 of 100 shared points.
colmap::Reconstruction LookingIn() {
  colmap::Reconstruction rec = Circle();
  rec.cameras[1] = {1, static_cast<int>(colmap::CameraModelId::kPinhole), 800, 600, {600, 600, 400, 300}};
  for (auto& [id, im] : rec.images) {
    im.camera_id = 1;
    const double a = 2 * M_PI * id / 20;
    LookFrom(&im, {4 * std::cos(a), 4 * std::sin(a), 1}, Eigen::Vector3d::Zero());
  }
  return rec;
}

TEST(BadPoses, FarAndTurnedAwayFromWhatTheOthersLookAtIsFound) {
  colmap::Reconstruction rec = LookingIn();
  EXPECT_TRUE(FindBadPoses(rec).empty());
  // At 2.5 times the median distance, looking past the object by 60 degrees, with all its
  // points: the pose of DSCF5644 in shared/data/bonsai.
  const Eigen::Vector3d far(10, 0, 1);
  const Eigen::Vector3d past = far + Eigen::AngleAxisd(M_PI / 3, Eigen::Vector3d::UnitZ()) * (-far);
  LookFrom(&rec.images[5], far, past);
  // Turned away as much but near, or far but looking at the object: kept.
  const Eigen::Vector3d near(4 * std::cos(2 * M_PI * 9 / 20), 4 * std::sin(2 * M_PI * 9 / 20), 1);
  LookFrom(&rec.images[9], near, near + Eigen::AngleAxisd(M_PI / 3, Eigen::Vector3d::UnitZ()) * (-near));
  LookFrom(&rec.images[13], {-9, 3, 1}, Eigen::Vector3d::Zero());
  const std::vector<BadPose> bad = FindBadPoses(rec);
  ASSERT_EQ(bad.size(), 1u);
  EXPECT_EQ(bad[0].name, "img5.jpg");
  EXPECT_EQ(bad[0].points, 80);
  EXPECT_NEAR(bad[0].away_degrees, 60.0, 1.5);
  EXPECT_NEAR(bad[0].from_looked_at / bad[0].median_from_looked_at, 10.05 / 4.12, 0.05);
  EXPECT_NE(bad[0].Describe().find("degrees off its axis and out of its view"), std::string::npos) << bad[0].Describe();
  // Without the cameras' intrinsics the second rule cannot tell what is in view: nothing found.
  rec.cameras.clear();
  EXPECT_TRUE(FindBadPoses(rec).empty());
}

TEST(BadPoses, TheFiveWrongPosesOfBonsai) {
  PERF_REQUIRE_DATA(bonsai, "bonsai");
  const colmap::Reconstruction rec = colmap::ReadReconstruction(bonsai / "sparse" / "0");
  std::vector<std::string> names;
  for (const BadPose& b : FindBadPoses(rec)) {
    names.push_back(b.name);
    std::printf("%s\n", b.Describe().c_str());
  }
  std::sort(names.begin(), names.end());  // FindBadPoses lists them in image-id order
  EXPECT_EQ(names, (std::vector<std::string>{"DSCF5644.JPG", "DSCF5647.JPG", "DSCF5842.JPG", "DSCF5845.JPG",
                                             "DSCF5848.JPG"}));
}

}  // namespace
}  // namespace perf
