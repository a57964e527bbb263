// The refined cameras handed back to the user (--refine-poses): every view's pose as the refined
// training cameras place it (scene.json's refined_world_from_cam), how far each training photo
// moved, and which moved so far that its imported pose was wrong rather than imprecise.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "recon_cuda/run/photo_corrections.h"
#include "workspace/scene.h"

namespace perf::recon {

// A correction over either bound is named (warning, recon.json) beside the bad-pose rules of
// import: it is more than refinement of a good registration.
inline constexpr double kLargeRotationDegrees = 1.0;
inline constexpr double kLargeCentreFraction = 0.02;  // of the camera's distance to the box centre
inline constexpr double kLargeFocalChange = 0.02;     // of the focal length (--refine-intrinsics focal)

struct PoseCorrection {
  std::string name;
  double rotation_degrees = 0;  // the angle between the imported and the refined camera
  double centre_shift = 0;      // world units
  double centre_fraction = 0;   // centre_shift over the imported camera's distance to the box centre
  double focal_change = 0;      // the refined focal length over the imported one, minus 1
  bool large = false;
  nlohmann::json ToJson() const;
};

// How far camera `to` is from camera `from` (world_from_cam [R | centre]): the angle between
// their rotations, the shift of the centre, and that shift over from's distance to `target` (0
// when from is there).
struct CameraMove {
  double degrees = 0, centre_shift = 0, centre_fraction = 0;
};
CameraMove MoveBetween(const Eigen::Matrix<double, 3, 4>& from, const Eigen::Matrix<double, 3, 4>& to,
                       const Eigen::Vector3d& target);

// The scene with refined_world_from_cam set on every image from `corrections` (a training image
// its own, the others the blend of their nearest training photos'); unchanged without poses.
Scene WithRefinedPoses(const Scene& scene, const PhotoCorrections& corrections);

// The scene posed as refined: world_from_cam replaced by refined_world_from_cam where set.
Scene PosedAsRefined(Scene scene);

// How far each training image with a refined pose moved, scene.json order.
std::vector<PoseCorrection> DescribeCorrections(const Scene& refined);

// "3 of 84 photos moved more than 1 degree or 2 % of their distance: DSCF5608 (1.4 deg, 0.6 %),
// ..."; empty when none did.
std::string LargeCorrectionsWarning(const std::vector<PoseCorrection>& corrections);

// recon.json's "poses": the median and largest corrections, the large ones and every photo's.
nlohmann::json CorrectionsToJson(const std::vector<PoseCorrection>& corrections);

}  // namespace perf::recon
