#include "recon_cuda/run/refined_poses.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "common/errors.h"
#include "recon_cuda/data/training_data.h"

namespace perf::recon {

namespace {
std::string Fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", digits, v);
  return buf;
}
}  // namespace

nlohmann::json PoseCorrection::ToJson() const {
  return {{"name", name},
          {"rotation_degrees", rotation_degrees},
          {"centre_shift", centre_shift},
          {"centre_fraction", centre_fraction},
          {"large", large}};
}

CameraMove MoveBetween(const Eigen::Matrix<double, 3, 4>& from, const Eigen::Matrix<double, 3, 4>& to,
                       const Eigen::Vector3d& target) {
  CameraMove m;
  const Eigen::Matrix3d r = from.leftCols<3>().transpose() * to.leftCols<3>();
  m.degrees = Eigen::AngleAxisd(r).angle() * 180 / std::numbers::pi;
  m.centre_shift = (to.col(3) - from.col(3)).norm();
  const double distance = (from.col(3) - target).norm();
  m.centre_fraction = distance > 0 ? m.centre_shift / distance : 0;
  return m;
}

Scene WithRefinedPoses(const Scene& scene, const PhotoCorrections& corrections) {
  Scene out = scene;
  if (!corrections.has_poses()) return out;
  const VolumeGeometry geometry = VolumeGeometry::FromScene(scene);
  for (SceneImage& im : out.images) {
    const PinholeCamera<float> camera = ToPinhole(scene.camera(im.camera_id), im.world_from_cam);
    const std::array<float, kPoseValues> pose = corrections.PoseFor(camera);
    double in[12], moved[12];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) in[4 * i + j] = im.world_from_cam(i, j);
    CorrectedPose(in, pose.data(), geometry, moved);
    Eigen::Matrix<double, 3, 4> refined;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) refined(i, j) = moved[4 * i + j];
    // Re-orthonormalised: the float rotation vector leaves the product a rotation to 1e-7.
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(refined.leftCols<3>(), Eigen::ComputeFullU | Eigen::ComputeFullV);
    refined.leftCols<3>() = svd.matrixU() * svd.matrixV().transpose();
    im.refined_world_from_cam = refined;
  }
  return out;
}

Scene PosedAsRefined(Scene scene) {
  for (SceneImage& im : scene.images) {
    if (im.refined_world_from_cam) im.world_from_cam = *im.refined_world_from_cam;
  }
  return scene;
}

std::vector<PoseCorrection> DescribeCorrections(const Scene& refined) {
  std::vector<PoseCorrection> out;
  for (const SceneImage& im : refined.images) {
    if (im.split != Split::kTrain || !im.refined_world_from_cam) continue;
    PoseCorrection c;
    c.name = im.name;
    const CameraMove m = MoveBetween(im.world_from_cam, *im.refined_world_from_cam, refined.box.center);
    c.rotation_degrees = m.degrees;
    c.centre_shift = m.centre_shift;
    c.centre_fraction = m.centre_fraction;
    c.large = c.rotation_degrees > kLargeRotationDegrees || c.centre_fraction > kLargeCentreFraction;
    out.push_back(c);
  }
  return out;
}

std::string LargeCorrectionsWarning(const std::vector<PoseCorrection>& corrections) {
  std::string names;
  int large = 0;
  for (const PoseCorrection& c : corrections) {
    if (!c.large) continue;
    if (++large <= 8) {
      names += StrCat(large > 1 ? ", " : "", c.name, " (", Fixed(c.rotation_degrees, 2), " deg, ",
                      Fixed(100 * c.centre_fraction, 1), " %)");
    }
  }
  if (large == 0) return "";
  return StrCat(large, " of ", corrections.size(), " photos moved more than ", kLargeRotationDegrees,
                " degree or ", 100 * kLargeCentreFraction, " % of their distance when refined: ", names,
                large > 8 ? ", ..." : "", "; their imported poses were wrong (check them in recon.json \"poses\")");
}

nlohmann::json CorrectionsToJson(const std::vector<PoseCorrection>& corrections) {
  nlohmann::json j = {{"refined", !corrections.empty()}};
  if (corrections.empty()) return j;
  std::vector<double> rot, centre;
  nlohmann::json photos = nlohmann::json::array(), large = nlohmann::json::array();
  for (const PoseCorrection& c : corrections) {
    rot.push_back(c.rotation_degrees);
    centre.push_back(c.centre_fraction);
    photos.push_back(c.ToJson());
    if (c.large) large.push_back(c.name);
  }
  const auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  j["median_rotation_degrees"] = median(rot);
  j["median_centre_fraction"] = median(centre);
  j["max_rotation_degrees"] = *std::max_element(rot.begin(), rot.end());
  j["max_centre_fraction"] = *std::max_element(centre.begin(), centre.end());
  j["large"] = large;
  j["photos"] = photos;
  return j;
}

}  // namespace perf::recon
