// Foreground masks in the photos' own frame (DESIGN.md "Rendering and masks"): the box opacity
// 1 - T_box of every input camera, at the photo's size on disk and, when the camera had
// distortion, in the distorted photo: each photo pixel looks up where its ray lands in the
// workspace's pinhole camera (Undistorter::MapFromDistorted), not a resize of the pinhole image.
#pragma once

#include <vector>

#include "recon_cuda/solve/backend.h"
#include "workspace/image.h"
#include "workspace/scene.h"

namespace perf::exporter {

// For every pixel of the photos of one camera (source width x height, row-major): its position
// in the workspace camera's pixels; NaN where the camera model has no ray for it.
struct PhotoFrame {
  int width = 0, height = 0;  // the photos on disk
  std::vector<float> x, y;
  bool identity_scale = false;  // pinhole source at the workspace's size: x, y are pixel centres

  // Throws InputError naming scene.json's camera when the source model cannot be inverted.
  static PhotoFrame Create(const SceneCamera& camera);
};

struct MaskOptions {
  // The workspace camera is rendered at this multiple of its size before the lookup; 1 is the
  // resolution the reconstruction was fitted at, and a 128^3 grid does not hold finer detail.
  double render_scale = 1.0;
};

// The soft mask (one channel, [0, 1]) of `image` at its photo's size and in its frame. The box
// opacity is rendered without the 0.7 rule (that rule is what the binary mask applies).
Image RenderPhotoMask(recon::Backend* backend, recon::VecId x, const SceneCamera& camera,
                      const SceneImage& image, const PhotoFrame& frame, const MaskOptions& options);

// The same at the workspace's size and frame (for evaluation against the workspace's alpha).
Image RenderWorkspaceMask(recon::Backend* backend, recon::VecId x, const SceneCamera& camera,
                          const SceneImage& image);

// 1 where soft >= threshold, else 0.
Image Binarize(const Image& soft, double threshold);

}  // namespace perf::exporter
