#include "recon_cuda/run/evaluation.h"

#include <cmath>

#include "common/errors.h"

namespace perf::recon {

double Psnr(const RenderOutput& render, const Image& truth) {
  PERF_CHECK(render.width == truth.width && render.height == truth.height && truth.channels == 3);
  double sse = 0;
  for (size_t i = 0; i < render.colour.size(); ++i) {
    const double d = static_cast<double>(std::clamp(render.colour[i], 0.f, 1.f)) - truth.pixels[i];
    sse += d * d;
  }
  return PsnrFromMse(sse / static_cast<double>(render.colour.size()));
}

Image ToImage(const RenderOutput& render) {
  Image im(render.width, render.height, 3);
  im.pixels = render.colour;
  return im;
}

Image OpacityImage(const RenderOutput& render) {
  Image im(render.width, render.height, 1);
  im.pixels = render.opacity;
  return im;
}

RenderOutput RenderAsShot(Backend* backend, VecId x, const PosedImage& view, float min_box_opacity,
                          const PhotoCorrections& exposures) {
  RenderOutput r =
      backend->Render(x, exposures.CameraFor(view.camera), view.image.width, view.image.height, min_box_opacity);
  if (!exposures.transforms().empty()) ApplyTransform(exposures.TransformFor(view.camera), &r);
  return r;
}

std::vector<ViewScore> ScoreViews(Backend* backend, VecId x, const std::vector<PosedImage>& views,
                                  float min_box_opacity, const PhotoCorrections& exposures) {
  std::vector<ViewScore> scores;
  for (const PosedImage& v : views) {
    scores.push_back({v.name, Psnr(RenderAsShot(backend, x, v, min_box_opacity, exposures), v.image)});
  }
  return scores;
}

double MeanPsnr(const std::vector<ViewScore>& scores) {
  if (scores.empty()) return 0;
  double s = 0;
  for (const ViewScore& v : scores) s += v.psnr;
  return s / static_cast<double>(scores.size());
}

}  // namespace perf::recon
