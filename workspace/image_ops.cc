// The parts of image_io.h that need no codec (image_ops.h has the rest): shared by the
// OpenImageIO implementation (image_io.cc) and perf_gpu's libpng one (image_io_via_png.cc).
#include <algorithm>
#include <array>
#include <cctype>
#include <string_view>

#include "common/errors.h"
#include "workspace/image_io.h"
#include "workspace/image_ops.h"

namespace fs = std::filesystem;

namespace perf {

int64_t DecodedBytes(const ImageInfo& info) {
  return int64_t{info.width} * info.height * std::min(info.channels, 4) * static_cast<int64_t>(sizeof(float));
}

Image MaskChannel(const Image& in) {
  const int c = (in.channels == 2 || in.channels == 4) ? in.channels - 1 : 0;
  Image out(in.width, in.height, 1);
  for (size_t p = 0; p < out.pixels.size(); ++p) out.pixels[p] = in.pixels[p * in.channels + c];
  return out;
}

Image ToRgb(const Image& in, const std::array<double, 3>& background, Image* alpha) {
  const bool has_alpha = in.channels == 2 || in.channels == 4;
  const int colour = has_alpha ? in.channels - 1 : in.channels;
  Image rgb(in.width, in.height, 3);
  if (has_alpha && alpha) *alpha = Image(in.width, in.height, 1);
  for (int y = 0; y < in.height; ++y) {
    for (int x = 0; x < in.width; ++x) {
      const float a = has_alpha ? in.at(x, y, in.channels - 1) : 1.f;
      for (int c = 0; c < 3; ++c) {
        const float v = in.at(x, y, colour == 1 ? 0 : c);
        rgb.at(x, y, c) = has_alpha ? v + (1.f - a) * static_cast<float>(background[c]) : v;
      }
      if (has_alpha && alpha) alpha->at(x, y, 0) = a;
    }
  }
  return rgb;
}

bool HasImageExtension(const fs::path& path) {
  static const std::array<std::string_view, 10> kExt = {".jpg", ".jpeg", ".png", ".tif", ".tiff",
                                                        ".exr", ".bmp", ".webp", ".hdr", ".dpx"};
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return std::find(kExt.begin(), kExt.end(), ext) != kExt.end();
}

Image AreaResize(const Image& image, int width, int height) {
  PERF_CHECK(width > 0 && height > 0 && width <= image.width && height <= image.height && !image.empty());
  if (width == image.width && height == image.height) return image;
  // Output pixel x covers source [x sx, (x + 1) sx): whole source pixels weigh 1, the two at its
  // ends their covered fraction (the same spans as a filtered resize, which maps the whole image
  // onto the whole output: training_data.h Downscaled scales the camera by the same ratio).
  const double sx = static_cast<double>(image.width) / width, sy = static_cast<double>(image.height) / height;
  struct Tap {
    int first = 0;
    std::vector<double> w;
  };
  const auto taps = [](int out, double scale, int in) {
    std::vector<Tap> t(out);
    for (int o = 0; o < out; ++o) {
      const double a = o * scale, b = std::min((o + 1) * scale, static_cast<double>(in));
      t[o].first = static_cast<int>(a);
      for (int i = t[o].first; i < b; ++i) t[o].w.push_back((std::min<double>(i + 1, b) - std::max<double>(i, a)) / (b - a));
    }
    return t;
  };
  const std::vector<Tap> tx = taps(width, sx, image.width), ty = taps(height, sy, image.height);
  Image out(width, height, image.channels);
  std::vector<double> acc(image.channels);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      std::fill(acc.begin(), acc.end(), 0.0);
      for (size_t j = 0; j < ty[y].w.size(); ++j) {
        for (size_t i = 0; i < tx[x].w.size(); ++i) {
          const double w = ty[y].w[j] * tx[x].w[i];
          for (int c = 0; c < image.channels; ++c) acc[c] += w * image.at(tx[x].first + static_cast<int>(i), ty[y].first + static_cast<int>(j), c);
        }
      }
      for (int c = 0; c < image.channels; ++c) out.at(x, y, c) = static_cast<float>(acc[c]);
    }
  }
  return out;
}

}  // namespace perf
