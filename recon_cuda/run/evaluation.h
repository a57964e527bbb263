// Rendering posed views with a backend and scoring them against their photos: the held-out PSNR
// of the reconstruction log, the previews written during a solve, and `perf render`.
#pragma once

#include <string>
#include <vector>

#include "recon_cuda/run/photo_corrections.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

struct ViewScore {
  std::string name;
  double psnr = 0;  // over all pixels and the three channels, values in [0, 1]
};

double Psnr(const RenderOutput& render, const Image& truth);
Image ToImage(const RenderOutput& render);          // RGB
Image OpacityImage(const RenderOutput& render);     // one channel: 1 - T_box

// A view rendered at its own size as its photo was shot: no jitter, the render rule at
// `min_box_opacity` (render_rule.h), from its camera as the refined training cameras place it and
// with the colour transform of its nearest training photos (photo_corrections.h CameraFor,
// TransformFor).
RenderOutput RenderAsShot(Backend* backend, VecId x, const PosedImage& view, float min_box_opacity,
                          const PhotoCorrections& exposures = {});

// Every view rendered as shot (RenderAsShot) and scored.
std::vector<ViewScore> ScoreViews(Backend* backend, VecId x, const std::vector<PosedImage>& views,
                                  float min_box_opacity, const PhotoCorrections& exposures = {});

// The mean of the per-view PSNRs (the NeRF convention); 0 for no views.
double MeanPsnr(const std::vector<ViewScore>& scores);

}  // namespace perf::recon
