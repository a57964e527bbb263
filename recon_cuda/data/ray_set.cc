// RaySet and MakeRaySet (training_data.h), apart from the image loading so that they link
// without OpenImageIO and TBB (the GPU benchmark).
#include "recon_cuda/data/training_data.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"

namespace perf::recon {

const RaySet& NoRays() {
  static const RaySet none;
  return none;
}

int64_t RaySet::Bytes() const {
  return static_cast<int64_t>(cameras.size() * (sizeof(PinholeCamera<float>) + sizeof(int32_t)) +
                              pixels.size() * sizeof(RayPixel) +
                              (colours.size() + alphas.size()) * sizeof(float));
}

bool ImagesHaveAlpha(const std::vector<PosedImage>& images) {
  return !images.empty() && std::all_of(images.begin(), images.end(), [](const PosedImage& im) {
    return im.alpha.width == im.image.width && im.alpha.height == im.image.height;
  });
}

RaySet MakeRaySet(const std::vector<PosedImage>& images) {
  RaySet rays;
  int64_t total = 0;
  for (const PosedImage& im : images) {
    if (im.image.width > 65535 || im.image.height > 65535) {
      throw InputError(im.name, "size", StrCat(im.image.width, "x", im.image.height), "images over 65535 pixels a side",
                       "re-run perf import with --downscale");
    }
    total += static_cast<int64_t>(im.image.width) * im.image.height;
  }
  const bool alpha = ImagesHaveAlpha(images);
  rays.pixels.reserve(total);
  rays.colours.reserve(3 * total);
  if (alpha) rays.alphas.reserve(total);
  constexpr int kTile = 8;
  for (size_t c = 0; c < images.size(); ++c) {
    const Image& img = images[c].image;
    rays.cameras.push_back(images[c].camera);
    rays.exposure_slot.push_back(static_cast<int32_t>(c));
    for (int ty = 0; ty < img.height; ty += kTile) {
      for (int tx = 0; tx < img.width; tx += kTile) {
        for (int y = ty; y < std::min(ty + kTile, img.height); ++y) {
          for (int x = tx; x < std::min(tx + kTile, img.width); ++x) {
            rays.pixels.push_back({static_cast<uint32_t>(c), static_cast<uint16_t>(x), static_cast<uint16_t>(y)});
            for (int ch = 0; ch < 3; ++ch) rays.colours.push_back(img.at(x, y, ch));
            if (alpha) rays.alphas.push_back(images[c].alpha.at(x, y, 0));
          }
        }
      }
    }
  }
  return rays;
}

double PixelsAcrossBox(std::span<const ViewFrustum> views, const VolumeGeometry& geo) {
  if (views.empty()) return 0;
  std::vector<double> pixels;
  const double side = std::min({geo.box.size.x, geo.box.size.y, geo.box.size.z});
  for (const ViewFrustum& view : views) {
    const PinholeCamera<float>& cam = view.camera;
    const float* m = cam.world_from_cam;
    const double dx = m[3] - geo.box.center.x, dy = m[7] - geo.box.center.y, dz = m[11] - geo.box.center.z;
    const double dist = std::max(1e-9, std::sqrt(dx * dx + dy * dy + dz * dz));
    pixels.push_back(cam.fx * side / dist);
  }
  std::nth_element(pixels.begin(), pixels.begin() + pixels.size() / 2, pixels.end());
  return pixels[pixels.size() / 2];
}

int PyramidFactor(std::span<const ViewFrustum> views, const VolumeGeometry& geo, int n, int max_factor) {
  if (views.empty() || max_factor <= 1) return 1;
  const double median = PixelsAcrossBox(views, geo) / n;  // pixels per voxel in the median view
  int f = 1;
  while (2 * f <= max_factor && median / (2 * f) >= 1.0) f *= 2;
  return f;
}

}  // namespace perf::recon
