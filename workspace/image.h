// A plain in-memory image: interleaved float channels, row-major, values in [0, 1] for
// integer sources (decoded as stored, i.e. sRGB-encoded for photos; no colour conversion).
#pragma once

#include <cstddef>
#include <vector>

namespace perf {

// How pixels were (or will be) stored on disk.
enum class PixelFormat { kUInt8, kUInt16, kHalf, kFloat };

struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;  // [height, width, channels]

  Image() = default;
  Image(int w, int h, int c)
      : width(w), height(h), channels(c), pixels(static_cast<size_t>(w) * h * c, 0.f) {}

  float& at(int x, int y, int c) {
    return pixels[(static_cast<size_t>(y) * width + x) * channels + c];
  }
  float at(int x, int y, int c) const {
    return pixels[(static_cast<size_t>(y) * width + x) * channels + c];
  }
  bool empty() const { return pixels.empty(); }
};

}  // namespace perf
