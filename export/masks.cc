#include "export/masks.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/run/evaluation.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_model.h"
#include "sfm_import/undistort.h"

namespace perf::exporter {

namespace {

// How far beyond the workspace image the rendered canvas may reach (in image sizes per side):
// strong fisheye photos map far outside the valid pinhole; beyond this the mask is 0.
constexpr double kMaxCanvasGrowth = 1.0;

}  // namespace

PhotoFrame PhotoFrame::Create(const SceneCamera& camera) {
  const std::string where = StrCat("scene.json camera ", camera.id);
  const colmap::CameraModelInfo* info = colmap::FindCameraModel(camera.source.model);
  if (info == nullptr) {
    throw InputError(where, "source.model", camera.source.model, "unknown camera model",
                     "re-run perf import on this workspace");
  }
  colmap::Camera source;
  source.camera_id = static_cast<uint32_t>(camera.id);
  source.model_id = static_cast<int>(info->id);
  source.width = static_cast<uint64_t>(camera.source.width);
  source.height = static_cast<uint64_t>(camera.source.height);
  source.params = camera.source.params;
  const Undistorter u = Undistorter::Create(source, where);
  PhotoFrame f;
  f.width = camera.source.width;
  f.height = camera.source.height;
  u.MapFromDistorted(&f.x, &f.y);
  // The workspace camera is the undistorted pinhole scaled to the workspace size (importer.cc).
  const double sx = static_cast<double>(camera.width) / u.pinhole().width;
  const double sy = static_cast<double>(camera.height) / u.pinhole().height;
  for (size_t i = 0; i < f.x.size(); ++i) {
    f.x[i] = static_cast<float>(f.x[i] * sx);
    f.y[i] = static_cast<float>(f.y[i] * sy);
  }
  f.identity_scale = u.is_identity() && sx == 1.0 && sy == 1.0;
  return f;
}

Image RenderWorkspaceMask(recon::Backend* backend, recon::VecId x, const SceneCamera& camera,
                          const SceneImage& image) {
  return recon::OpacityImage(
      backend->Render(x, recon::ToPinhole(camera, image.world_from_cam), camera.width, camera.height, 0.f));
}

Image RenderPhotoMask(recon::Backend* backend, recon::VecId x, const SceneCamera& camera,
                      const SceneImage& image, const PhotoFrame& frame, const MaskOptions& options) {
  PERF_CHECK(frame.x.size() == static_cast<size_t>(frame.width) * frame.height);
  if (frame.identity_scale && options.render_scale == 1.0) return RenderWorkspaceMask(backend, x, camera, image);

  // The canvas: the workspace camera grown to cover where the photo's pixels land, rendered at
  // render_scale, then looked up bilinearly per photo pixel.
  double x0 = 0, y0 = 0, x1 = camera.width, y1 = camera.height;
  for (size_t i = 0; i < frame.x.size(); ++i) {
    if (std::isnan(frame.x[i])) continue;
    x0 = std::min(x0, static_cast<double>(frame.x[i]));
    x1 = std::max(x1, static_cast<double>(frame.x[i]));
    y0 = std::min(y0, static_cast<double>(frame.y[i]));
    y1 = std::max(y1, static_cast<double>(frame.y[i]));
  }
  x0 = std::max(std::floor(x0) - 1, -kMaxCanvasGrowth * camera.width);
  y0 = std::max(std::floor(y0) - 1, -kMaxCanvasGrowth * camera.height);
  x1 = std::min(std::ceil(x1) + 1, (1 + kMaxCanvasGrowth) * camera.width);
  y1 = std::min(std::ceil(y1) + 1, (1 + kMaxCanvasGrowth) * camera.height);
  const double s = options.render_scale;
  const int cw = std::max(1, static_cast<int>(std::lround((x1 - x0) * s)));
  const int ch = std::max(1, static_cast<int>(std::lround((y1 - y0) * s)));
  recon::PinholeCamera<float> pin = recon::ToPinhole(camera, image.world_from_cam);
  // Canvas pixel (u, v) = s (workspace pixel - origin): pixel edges map to pixel edges.
  pin.fx = static_cast<float>(camera.fx * s);
  pin.fy = static_cast<float>(camera.fy * s);
  pin.cx = static_cast<float>((camera.cx - x0) * s);
  pin.cy = static_cast<float>((camera.cy - y0) * s);
  const recon::RenderOutput r = backend->Render(x, pin, cw, ch, 0.f);

  // cv::remap wants OpenCV pixel coordinates (upper-left centre at 0); NaN and far-off
  // positions read the constant border 0.
  cv::Mat map_x(frame.height, frame.width, CV_32FC1), map_y(frame.height, frame.width, CV_32FC1);
  for (int j = 0; j < frame.height; ++j) {
    float* mx = map_x.ptr<float>(j);
    float* my = map_y.ptr<float>(j);
    for (int i = 0; i < frame.width; ++i) {
      const size_t k = static_cast<size_t>(j) * frame.width + i;
      const bool ok = !std::isnan(frame.x[k]);
      mx[i] = ok ? static_cast<float>((frame.x[k] - x0) * s - 0.5) : -1e6f;
      my[i] = ok ? static_cast<float>((frame.y[k] - y0) * s - 0.5) : -1e6f;
    }
  }
  const cv::Mat src(ch, cw, CV_32FC1, const_cast<float*>(r.opacity.data()));
  Image out(frame.width, frame.height, 1);
  cv::Mat dst(frame.height, frame.width, CV_32FC1, out.pixels.data());
  cv::remap(src, dst, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
  PERF_CHECK(dst.data == reinterpret_cast<const uchar*>(out.pixels.data()));
  return out;
}

Image Binarize(const Image& soft, double threshold) {
  Image out(soft.width, soft.height, 1);
  for (size_t i = 0; i < out.pixels.size(); ++i) out.pixels[i] = soft.pixels[i * soft.channels] >= threshold ? 1.f : 0.f;
  return out;
}

}  // namespace perf::exporter
