#include "recon_cuda/run/exposure.h"

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

PhotoExposures::PhotoExposures(const VolumeShape& shape, std::span<const float> params,
                               std::span<const ViewFrustum> train_views) {
  if (shape.exposures == 0) return;
  PERF_CHECK(static_cast<int64_t>(params.size()) == shape.ParamCount());
  PERF_CHECK_MSG(static_cast<int>(train_views.size()) == shape.exposures, train_views.size(), " training views for ",
                 shape.exposures, " exposures");
  for (int k = 0; k < shape.exposures; ++k) {
    transforms_.push_back(TransformOf(params.data(), shape.ExposureStart(), k));
    centres_.push_back(Centre(train_views[k].camera));
  }
}

ColourTransform<float> PhotoExposures::Nearest(const PinholeCamera<float>& camera) const {
  // The two nearest camera centres, their transforms weighted by inverse distance (a view between
  // two shots of a drifting exposure takes the value between them; one at a photo's own centre
  // takes that photo's).
  const Vec3<double> c = Centre(camera);
  double d0 = std::numeric_limits<double>::infinity(), d1 = d0;
  int k0 = -1, k1 = -1;
  for (size_t k = 0; k < centres_.size(); ++k) {
    const Vec3<double> d = centres_[k] - c;
    const double dist = std::sqrt(Dot(d, d));
    if (dist < d0) {
      d1 = d0, k1 = k0;
      d0 = dist, k0 = static_cast<int>(k);
    } else if (dist < d1) {
      d1 = dist, k1 = static_cast<int>(k);
    }
  }
  ColourTransform<float> xf;
  if (k0 < 0) return xf;
  if (k1 < 0 || d0 <= 1e-9 * d1) return transforms_[k0];
  const double w0 = 1 / d0, w1 = 1 / d1, sum = w0 + w1;
  for (int ch = 0; ch < 3; ++ch) {
    xf.gain[ch] = static_cast<float>((w0 * transforms_[k0].gain[ch] + w1 * transforms_[k1].gain[ch]) / sum);
    xf.offset[ch] = static_cast<float>((w0 * transforms_[k0].offset[ch] + w1 * transforms_[k1].offset[ch]) / sum);
  }
  return xf;
}

void ApplyTransform(const ColourTransform<float>& xf, RenderOutput* render) {
  for (size_t i = 0; i < render->colour.size(); ++i) {
    const int c = static_cast<int>(i % 3);
    render->colour[i] = xf.gain[c] * render->colour[i] + xf.offset[c];
  }
}

}  // namespace perf::recon
