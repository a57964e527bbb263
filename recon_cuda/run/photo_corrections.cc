#include "recon_cuda/run/photo_corrections.h"

#include <cmath>
#include <limits>

#include "common/errors.h"
#include "recon_cuda/core/training_ray.h"

namespace perf::recon {

namespace {
Vec3<double> Centre(const PinholeCamera<float>& c) {
  return {c.world_from_cam[3], c.world_from_cam[7], c.world_from_cam[11]};
}
}  // namespace

PhotoCorrections::PhotoCorrections(const VolumeShape& shape, std::span<const float> params,
                                   std::span<const ViewFrustum> train_views, const VolumeGeometry& geometry)
    : geometry_(geometry) {
  if (shape.exposures == 0 && shape.poses == 0) return;
  PERF_CHECK(static_cast<int64_t>(params.size()) == shape.ParamCount());
  for (int count : {shape.exposures, shape.poses}) {
    PERF_CHECK_MSG(count == 0 || static_cast<int>(train_views.size()) == count, train_views.size(),
                   " training views for ", count, " photos' values");
  }
  for (const ViewFrustum& v : train_views) centres_.push_back(Centre(v.camera));
  for (int k = 0; k < shape.exposures; ++k) transforms_.push_back(TransformOf(params.data(), shape.ExposureStart(), k));
  for (int k = 0; k < shape.poses; ++k) {
    std::array<float, kPoseValues> p;
    for (int j = 0; j < kPoseValues; ++j) p[j] = params[PoseParam(shape.PoseStart(), k) + j];
    poses_.push_back(p);
  }
}

PhotoCorrections::Blend PhotoCorrections::NearestTwo(const PinholeCamera<float>& camera) const {
  // The two nearest camera centres weighted by inverse distance (a view between two shots takes
  // the value between them; one at a photo's own centre takes that photo's).
  const Vec3<double> c = Centre(camera);
  double d0 = std::numeric_limits<double>::infinity(), d1 = d0;
  Blend b;
  for (size_t k = 0; k < centres_.size(); ++k) {
    const Vec3<double> d = centres_[k] - c;
    const double dist = std::sqrt(Dot(d, d));
    if (dist < d0) {
      d1 = d0, b.k1 = b.k0;
      d0 = dist, b.k0 = static_cast<int>(k);
    } else if (dist < d1) {
      d1 = dist, b.k1 = static_cast<int>(k);
    }
  }
  if (b.k0 < 0) return b;
  if (b.k1 < 0 || d0 <= 1e-9 * d1) {
    b.w0 = 1;
    b.k1 = -1;
    return b;
  }
  const double w0 = 1 / d0, w1 = 1 / d1;
  b.w0 = w0 / (w0 + w1);
  b.w1 = w1 / (w0 + w1);
  return b;
}

ColourTransform<float> PhotoCorrections::TransformFor(const PinholeCamera<float>& camera) const {
  ColourTransform<float> xf;
  if (transforms_.empty()) return xf;
  const Blend b = NearestTwo(camera);
  if (b.k0 < 0) return xf;
  if (b.k1 < 0) return transforms_[b.k0];
  const ColourTransform<float>&t0 = transforms_[b.k0], &t1 = transforms_[b.k1];
  for (int ch = 0; ch < 3; ++ch) {
    xf.gain[ch] = static_cast<float>(b.w0 * t0.gain[ch] + b.w1 * t1.gain[ch]);
    xf.offset[ch] = static_cast<float>(b.w0 * t0.offset[ch] + b.w1 * t1.offset[ch]);
  }
  return xf;
}

std::array<float, kPoseValues> PhotoCorrections::PoseFor(const PinholeCamera<float>& camera) const {
  std::array<float, kPoseValues> p{};
  if (poses_.empty()) return p;
  const Blend b = NearestTwo(camera);
  if (b.k0 < 0) return p;
  for (int j = 0; j < kPoseValues; ++j) {
    p[j] = static_cast<float>(b.w0 * poses_[b.k0][j] + (b.k1 < 0 ? 0.0 : b.w1 * poses_[b.k1][j]));
  }
  return p;
}

PinholeCamera<float> PhotoCorrections::CameraFor(const PinholeCamera<float>& camera) const {
  if (poses_.empty()) return camera;
  return CorrectedCamera(camera, PoseFor(camera).data(), geometry_);
}

PinholeCamera<float> CorrectedCamera(const PinholeCamera<float>& camera, const float* pose,
                                     const VolumeGeometry& geometry) {
  PinholeCamera<float> out = camera;
  CorrectedPose(camera.world_from_cam, pose, geometry, out.world_from_cam);
  out.fx = camera.fx * FocalScale(pose);
  out.fy = camera.fy * FocalScale(pose);
  return out;
}

void ApplyTransform(const ColourTransform<float>& xf, RenderOutput* render) {
  for (size_t i = 0; i < render->colour.size(); ++i) {
    const int c = static_cast<int>(i % 3);
    render->colour[i] = xf.gain[c] * render->colour[i] + xf.offset[c];
  }
}

}  // namespace perf::recon
