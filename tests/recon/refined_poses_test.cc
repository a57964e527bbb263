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

}  // namespace
}  // namespace perf::recon
