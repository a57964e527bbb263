// The training photos' own parameters outside the solve: the exposures (ray_types.h
// ExposureParam) and the pose corrections (PoseParam) a parameter vector holds, what they imply
// for a view that was not trained on, and applying them to a render so that it is compared with
// the photo as the photo was shot.
//
// A held-out view takes the values of the two training photos whose camera centres are nearest
// its own, weighted by inverse distance: shots moments apart share a drifting exposure, which the
// blend interpolates and the nearest photo alone does not (docs/tuning.md "Per-photo exposure");
// a refined camera's neighbours' corrections carry whatever moved the set as a whole (the gauge
// the pose prior leaves, a drift of the capture) to it. A training view finds its own. Fitting a
// held-out view's values to its photo would use the photo being scored; the headline scores do
// not (the test-time pose fit is reported beside them, labelled).
#pragma once

#include <array>
#include <cmath>
#include <span>
#include <vector>

#include "recon_cuda/core/pose.h"
#include "recon_cuda/data/volume.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

class PhotoCorrections {
 public:
  PhotoCorrections() = default;  // none: every view renders as solved and as posed
  // The shape's exposures and pose corrections from params, photo k's at the camera centre of
  // train_views[k] (every training view, scene.json order; as many as the shape solves); the
  // poses are in the box frame of `geometry`. Without either in the shape: none of that kind.
  PhotoCorrections(const VolumeShape& shape, std::span<const float> params, std::span<const ViewFrustum> train_views,
                   const VolumeGeometry& geometry);

  bool empty() const { return transforms_.empty() && poses_.empty(); }
  bool has_poses() const { return !poses_.empty(); }
  const std::vector<ColourTransform<float>>& transforms() const { return transforms_; }
  // The colour transform for a view from `camera` (above; the identity without exposures).
  ColourTransform<float> TransformFor(const PinholeCamera<float>& camera) const;
  // The pose values (PoseParam order) for a view from `camera` (above; zeros without poses).
  std::array<float, kPoseValues> PoseFor(const PinholeCamera<float>& camera) const;
  // The view's camera moved by PoseFor (itself without poses).
  PinholeCamera<float> CameraFor(const PinholeCamera<float>& camera) const;

 private:
  struct Blend {
    int k0 = -1, k1 = -1;
    double w0 = 0, w1 = 0;  // weights summing to 1; w1 = 0: k0 alone
  };
  Blend NearestTwo(const PinholeCamera<float>& camera) const;

  std::vector<ColourTransform<float>> transforms_;
  std::vector<std::array<float, kPoseValues>> poses_;
  std::vector<Vec3<double>> centres_;
  VolumeGeometry geometry_;
};

// The pose whose rays are those of world_from_cam (row-major 3x4 [R | c]) moved by pose values
// `pose` (PoseParam order) in the box frame of `geometry` (pose.h ApplyPose): R becomes
// R_box exp([w]x) R_box^T R and the centre c becomes c + R_box (s t), s the box's shortest side.
// In the scalar of the pose (float for rendering, double for scene.json and COLMAP models).
template <class T>
void CorrectedPose(const T* world_from_cam, const float* pose, const VolumeGeometry& geometry, T* out) {
  Mat3<double> rot, unused;
  RotationOfVector(Vec3<double>{pose[0], pose[1], pose[2]}, &rot, &unused);
  double rb[9], m[9], tmp[9];
  for (int i = 0; i < 9; ++i) rb[i] = geometry.box.world_from_box.m[i];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      tmp[3 * i + j] = 0;
      for (int k = 0; k < 3; ++k) tmp[3 * i + j] += rb[3 * i + k] * rot.m[3 * k + j];
    }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      m[3 * i + j] = 0;
      for (int k = 0; k < 3; ++k) m[3 * i + j] += tmp[3 * i + k] * rb[3 * j + k];  // (R_box exp) R_box^T
    }
  const double scale = Min(geometry.box.size.x, Min(geometry.box.size.y, geometry.box.size.z));
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double s = 0;
      for (int k = 0; k < 3; ++k) s += m[3 * i + k] * world_from_cam[4 * k + j];
      out[4 * i + j] = static_cast<T>(s);
    }
    double shift = 0;
    for (int k = 0; k < 3; ++k) shift += rb[3 * i + k] * scale * pose[4 + k];
    out[4 * i + 3] = static_cast<T>(world_from_cam[4 * i + 3] + shift);
  }
}

// How much pose values `pose` scale the focal length: exp(f), f its value 3 (pose.h ApplyPose).
inline double FocalScale(const float* pose) { return std::exp(static_cast<double>(pose[3])); }

// The camera moved by `pose` (CorrectedPose), its fx and fy scaled by FocalScale.
PinholeCamera<float> CorrectedCamera(const PinholeCamera<float>& camera, const float* pose,
                                     const VolumeGeometry& geometry);

// render.colour = gain * colour + offset, pixel by pixel (the render as the photo would show it).
void ApplyTransform(const ColourTransform<float>& xf, RenderOutput* render);

}  // namespace perf::recon
