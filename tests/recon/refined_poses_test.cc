// How far refined cameras moved (refined_poses.h): the angle and the centre's shift of each
// training photo, the large ones named, and recon.json's summary.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <numbers>

#include "recon_cuda/run/refined_poses.h"

namespace perf::recon {
namespace {

TEST(RefinedPoses, CorrectionsAreMeasuredAndLargeOnesNamed) {
  Scene s;
  s.box.center = Eigen::Vector3d(0, 0, 0);
  const auto image = [&](const std::string& name, Split split, double degrees, double shift) {
    SceneImage im;
    im.name = name;
    im.split = split;
    im.world_from_cam.col(3) = Eigen::Vector3d(0, 0, -4);  // 4 units from the box centre
    Eigen::Matrix<double, 3, 4> refined = im.world_from_cam;
    refined.leftCols<3>() = Eigen::AngleAxisd(degrees * std::numbers::pi / 180, Eigen::Vector3d::UnitY()).matrix();
    refined.col(3) += Eigen::Vector3d(shift, 0, 0);
    im.refined_world_from_cam = refined;
    s.images.push_back(im);
  };
  image("turned", Split::kTrain, 2.0, 0.0);     // 2 degrees: large
  image("nudged", Split::kTrain, 0.3, 0.02);    // 0.5 % of 4 units: not large
  image("shifted", Split::kTrain, 0.0, 0.12);   // 3 %: large
  image("held out", Split::kTest, 5.0, 1.0);    // not a training photo: not described
  const std::vector<PoseCorrection> c = DescribeCorrections(s);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_NEAR(c[0].rotation_degrees, 2.0, 1e-9);
  EXPECT_NEAR(c[1].centre_fraction, 0.005, 1e-9);
  EXPECT_NEAR(c[2].centre_shift, 0.12, 1e-12);
  EXPECT_TRUE(c[0].large);
  EXPECT_FALSE(c[1].large);
  EXPECT_TRUE(c[2].large);
  const std::string warning = LargeCorrectionsWarning(c);
  EXPECT_NE(warning.find("2 of 3 photos"), std::string::npos) << warning;
  EXPECT_NE(warning.find("turned (2.00 deg"), std::string::npos) << warning;
  EXPECT_NE(warning.find("shifted"), std::string::npos) << warning;
  EXPECT_EQ(warning.find("nudged"), std::string::npos) << warning;
  const nlohmann::json j = CorrectionsToJson(c);
  EXPECT_NEAR(j["median_rotation_degrees"].get<double>(), 0.3, 1e-9);
  EXPECT_NEAR(j["max_centre_fraction"].get<double>(), 0.03, 1e-9);
  EXPECT_EQ(j["large"].size(), 2u);
  EXPECT_TRUE(LargeCorrectionsWarning({c[1]}).empty());
  EXPECT_FALSE(CorrectionsToJson({})["refined"].get<bool>());
}

// --refine-intrinsics focal: a focal length's change is measured and named like a move, scene.json
// keeps it, and the scene posed as refined gives that photo its own camera with the focal scaled.
TEST(RefinedPoses, FocalLengthsAreMeasuredKeptAndApplied) {
  Scene s;
  SceneCamera cam;
  cam.id = 3;
  cam.width = 40;
  cam.height = 30;
  cam.fx = 50;
  cam.fy = 52;
  cam.cx = 20;
  cam.cy = 15;
  cam.source = {"PINHOLE", {50, 52, 20, 15}, 40, 30};
  s.cameras.push_back(cam);
  for (const auto& [name, scale] : {std::pair{"zoomed", 1.03}, std::pair{"kept", 1.005}}) {
    SceneImage im;
    im.name = name;
    im.path = std::string("images/") + name + ".png";
    im.camera_id = 3;
    im.world_from_cam.col(3) = Eigen::Vector3d(0, 0, -4);
    im.refined_world_from_cam = im.world_from_cam;
    im.refined_focal_scale = scale;
    s.images.push_back(im);
  }
  const std::vector<PoseCorrection> c = DescribeCorrections(s);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_NEAR(c[0].focal_change, 0.03, 1e-12);
  EXPECT_TRUE(c[0].large);
  EXPECT_FALSE(c[1].large);
  const std::string warning = LargeCorrectionsWarning(c);
  EXPECT_NE(warning.find("zoomed (0.00 deg, 0.0 %, focal +3.0 %)"), std::string::npos) << warning;
  EXPECT_NE(warning.find("changed focal length by more than 2 %"), std::string::npos) << warning;
  EXPECT_NEAR(CorrectionsToJson(c)["max_focal_change"].get<double>(), 0.03, 1e-12);

  const Scene posed = PosedAsRefined(s);
  ASSERT_EQ(posed.cameras.size(), 3u);  // each refined photo its own camera; the imported one stays
  EXPECT_EQ(posed.camera(3).fx, 50);
  const SceneCamera& zoomed = posed.camera(posed.images[0].camera_id);
  EXPECT_NE(zoomed.id, 3);
  EXPECT_NEAR(zoomed.fx, 51.5, 1e-12);
  EXPECT_NEAR(zoomed.fy, 52 * 1.03, 1e-12);
  EXPECT_EQ(zoomed.cx, 20);
  EXPECT_NE(posed.images[0].camera_id, posed.images[1].camera_id);
}

}  // namespace
}  // namespace perf::recon
