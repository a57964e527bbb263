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
          {"focal_change", focal_change},
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
    if (pose[3] != 0.f) {
      im.refined_focal_scale = FocalScale(pose.data());
    } else {
      im.refined_focal_scale.reset();
    }
  }
  return out;
}

Scene PosedAsRefined(Scene scene) {
  int next_id = 0;
  for (const SceneCamera& c : scene.cameras) next_id = std::max(next_id, c.id + 1);
  for (SceneImage& im : scene.images) {
    if (im.refined_world_from_cam) im.world_from_cam = *im.refined_world_from_cam;
    if (im.refined_focal_scale) {  // its own camera: the focal length is the photo's
      SceneCamera c = scene.camera(im.camera_id);
      c.id = next_id++;
      c.fx *= *im.refined_focal_scale;
      c.fy *= *im.refined_focal_scale;
      scene.cameras.push_back(c);
      im.camera_id = c.id;
    }
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
    c.focal_change = im.refined_focal_scale ? *im.refined_focal_scale - 1 : 0;
    c.large = c.rotation_degrees > kLargeRotationDegrees || c.centre_fraction > kLargeCentreFraction ||
              std::abs(c.focal_change) > kLargeFocalChange;
    out.push_back(c);
  }
  return out;
}

std::string LargeCorrectionsWarning(const std::vector<PoseCorrection>& corrections) {
  std::string names;
  int large = 0;
  bool focal = false;
  for (const PoseCorrection& c : corrections) focal = focal || c.focal_change != 0;
  for (const PoseCorrection& c : corrections) {
    if (!c.large) continue;
    if (++large <= 8) {
      names += StrCat(large > 1 ? ", " : "", c.name, " (", Fixed(c.rotation_degrees, 2), " deg, ",
                      Fixed(100 * c.centre_fraction, 1), " %",
                      focal ? StrCat(", focal ", c.focal_change >= 0 ? "+" : "", Fixed(100 * c.focal_change, 1), " %")
                            : std::string(),
                      ")");
    }
  }
  if (large == 0) return "";
  return StrCat(large, " of ", corrections.size(), " photos moved more than ", kLargeRotationDegrees,
                " degree or ", 100 * kLargeCentreFraction, " % of their distance",
                focal ? StrCat(" or changed focal length by more than ", 100 * kLargeFocalChange, " %") : std::string(),
                " when refined: ", names,
                large > 8 ? ", ..." : "", "; their imported poses were wrong (check them in recon.json \"poses\")");
}

nlohmann::json CorrectionsToJson(const std::vector<PoseCorrection>& corrections) {
  nlohmann::json j = {{"refined", !corrections.empty()}};
  if (corrections.empty()) return j;
  std::vector<double> rot, centre, focal;
  nlohmann::json photos = nlohmann::json::array(), large = nlohmann::json::array();
  for (const PoseCorrection& c : corrections) {
    rot.push_back(c.rotation_degrees);
    centre.push_back(c.centre_fraction);
    focal.push_back(std::abs(c.focal_change));
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
  j["max_focal_change"] = *std::max_element(focal.begin(), focal.end());
  j["large"] = large;
  j["photos"] = photos;
  return j;
}

}  // namespace perf::recon
