#include "recon_cuda/data/training_data.h"

#include <tbb/parallel_for.h>

#include <atomic>

#include "common/errors.h"
#include "workspace/image_io.h"

namespace perf::recon {

PinholeCamera<float> ToPinhole(const SceneCamera& camera, const Eigen::Matrix<double, 3, 4>& world_from_cam) {
  PinholeCamera<float> c{};
  c.fx = static_cast<float>(camera.fx);
  c.fy = static_cast<float>(camera.fy);
  c.cx = static_cast<float>(camera.cx);
  c.cy = static_cast<float>(camera.cy);
  for (int i = 0; i < 12; ++i) c.world_from_cam[i] = static_cast<float>(world_from_cam(i / 4, i % 4));
  return c;
}

Eigen::Matrix<double, 3, 4> WorldFromCam(const PinholeCamera<float>& camera) {
  return Eigen::Matrix<float, 3, 4, Eigen::RowMajor>(camera.world_from_cam).cast<double>();
}

std::vector<ViewFrustum> SplitViews(const Scene& scene, Split split) {
  std::vector<ViewFrustum> views;
  for (const SceneImage& im : scene.images) {
    if (im.split != split) continue;
    const SceneCamera& cam = scene.camera(im.camera_id);
    views.push_back({ToPinhole(cam, im.world_from_cam), cam.width, cam.height});
  }
  return views;
}

IndexRange ShareOfSplit(const Scene& scene, Split split, ImageShare share) {
  std::vector<double> pixels;
  for (const SceneImage& im : scene.images) {
    if (im.split != split) continue;
    const SceneCamera& cam = scene.camera(im.camera_id);
    pixels.push_back(static_cast<double>(cam.width) * cam.height);
  }
  return ContiguousShare(pixels, share.rank, share.size);
}

std::vector<PosedImage> LoadImages(const Scene& scene, const std::filesystem::path& workspace, Split split,
                                   const std::function<void(int done, int total)>& progress, ImageShare share) {
  std::vector<const SceneImage*> chosen;
  for (const SceneImage& im : scene.images) {
    if (im.split == split) chosen.push_back(&im);
  }
  if (share.size > 1) {
    const IndexRange mine = ShareOfSplit(scene, split, share);
    chosen = std::vector<const SceneImage*>(chosen.begin() + static_cast<ptrdiff_t>(mine.begin),
                                            chosen.begin() + static_cast<ptrdiff_t>(mine.end));
  }
  std::vector<PosedImage> out(chosen.size());
  std::atomic<int> done{0};
  tbb::parallel_for(size_t{0}, chosen.size(), [&](size_t i) {
    const SceneImage& im = *chosen[i];
    const SceneCamera& cam = scene.camera(im.camera_id);
    const std::filesystem::path path = workspace / im.path;
    // The importer writes RGB; an RGBA image put there since is composited like on import.
    Image img = ToRgb(ReadImage(path), {scene.background.x(), scene.background.y(), scene.background.z()});
    if (img.width != cam.width || img.height != cam.height) {
      throw InputError(path.string(), "size", StrCat(img.width, "x", img.height),
                       StrCat("scene.json says camera ", cam.id, " is ", cam.width, "x", cam.height),
                       "the workspace images were changed after import; re-run perf import");
    }
    Image alpha;
    if (!im.alpha_path.empty()) {
      const std::filesystem::path apath = workspace / im.alpha_path;
      alpha = MaskChannel(ReadImage(apath));
      if (alpha.width != cam.width || alpha.height != cam.height) {
        throw InputError(apath.string(), "size", StrCat(alpha.width, "x", alpha.height),
                         StrCat("the image ", im.path, " is ", cam.width, "x", cam.height),
                         "the workspace alpha images were changed after import; re-run perf import");
      }
    }
    out[i] = {im.name, ToPinhole(cam, im.world_from_cam), std::move(img), std::move(alpha)};
    const int d = ++done;
    if (progress) progress(d, static_cast<int>(chosen.size()));
  });
  return out;
}

PosedImage Downscaled(const PosedImage& image, int factor) {
  if (factor <= 1) return image;
  PosedImage out = image;
  const int w = std::max(1, image.image.width / factor), h = std::max(1, image.image.height / factor);
  out.image = ResizeImage(image.image, w, h);
  if (image.alpha.width > 0) out.alpha = ResizeImage(image.alpha, w, h);
  // The resized image covers the same field of view: scale by the exact per-axis ratio.
  const float sx = static_cast<float>(w) / image.image.width, sy = static_cast<float>(h) / image.image.height;
  out.camera.fx *= sx;
  out.camera.cx *= sx;
  out.camera.fy *= sy;
  out.camera.cy *= sy;
  return out;
}

std::vector<PosedImage> DownscaledAll(const std::vector<PosedImage>& images, int factor) {
  std::vector<PosedImage> out(images.size());
  tbb::parallel_for(size_t{0}, images.size(), [&](size_t i) { out[i] = Downscaled(images[i], factor); });
  return out;
}

}  // namespace perf::recon
