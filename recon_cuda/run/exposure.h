// The photos' exposures outside the solve: reading the transforms a parameter vector
// holds (ray_types.h ExposureParam), choosing one for a view that was not trained on, and applying
// it to a render so that it is compared with the photo as the photo was exposed.
//
// A held-out view takes the transforms of the two training photos whose camera centres are
// nearest its own, weighted by inverse distance: shots moments apart share a drifting exposure,
// which the blend interpolates and the nearest photo alone does not (docs/tuning.md "Per-photo
// exposure"); a training view finds its own. Fitting a held-out view's transform to its photo
// would use the photo being scored (as some papers do with half the image); we do not.
#pragma once

#include <span>
#include <vector>

#include "recon_cuda/data/volume.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

class PhotoExposures {
 public:
  PhotoExposures() = default;  // none: every view renders as solved (the identity)
  // shape.exposures transforms from params, photo k's at the camera centre of train_views[k]
  // (every training view, scene.json order; as many as shape.exposures). Without exposures in the
  // shape: none.
  PhotoExposures(const VolumeShape& shape, std::span<const float> params, std::span<const ViewFrustum> train_views);

  bool empty() const { return transforms_.empty(); }
  const std::vector<ColourTransform<float>>& transforms() const { return transforms_; }
  // The transform for a view from `camera` (above; the identity when empty).
  ColourTransform<float> Nearest(const PinholeCamera<float>& camera) const;

 private:
  std::vector<ColourTransform<float>> transforms_;
  std::vector<Vec3<double>> centres_;
};

// render.colour = gain * colour + offset, pixel by pixel (the render as the photo would show it).
void ApplyTransform(const ColourTransform<float>& xf, RenderOutput* render);

}  // namespace perf::recon
