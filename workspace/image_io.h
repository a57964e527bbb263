// Image input/output through OpenImageIO: JPEG, PNG (8/16-bit), TIFF, EXR and whatever else
// OIIO reads; RGB, RGBA or grey. Pixels are returned as stored (no EXIF reorientation), which
// is the orientation COLMAP used when it detected features.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>

#include "workspace/image.h"

namespace perf {

struct ImageInfo {
  int width = 0, height = 0, channels = 0;
  PixelFormat format = PixelFormat::kUInt8;
};

// Reads only the header. Throws InputError if the file is not a readable image, or larger
// than PERF reads (65536 pixels a side, 2^30 pixels).
ImageInfo ReadImageInfo(const std::filesystem::path& path);

// What a photo's header says about the camera that took it (EXIF where present; empty or 0
// where not). Throws like ReadImageInfo.
struct CameraTags {
  int width = 0, height = 0;
  std::string make, model;     // EXIF Make, Model
  double focal_mm = 0;         // EXIF FocalLength
  std::string time;            // EXIF DateTimeOriginal ("YYYY:MM:DD HH:MM:SS")
};
CameraTags ReadCameraTags(const std::filesystem::path& path);

// Bytes ReadImage allocates for an image of this header.
int64_t DecodedBytes(const ImageInfo& info);

// Reads the whole image as float. `info` (optional) receives the stored format. Images with
// alpha come back with associated (premultiplied) colour, OpenImageIO's default. Throws
// InputError on truncated or corrupt data (decoder warnings included), ResourceError when the
// decoded image would not fit in the available memory.
Image ReadImage(const std::filesystem::path& path, ImageInfo* info = nullptr);

// Writes atomically; the file format follows the extension. Values are clamped to [0, 1] for
// integer formats.
void WriteImage(const std::filesystem::path& path, const Image& image, PixelFormat format);

// Filtered resize (OIIO's ImageBufAlgo::resize, default filter: blackman-harris for
// downscaling) to exactly `width` x `height`.
Image ResizeImage(const Image& image, int width, int height);

// RGB from grey, grey + alpha, RGB or RGBA: alpha is split off into `alpha` (optional) and the
// colour composited over `background`. OpenImageIO returns associated (premultiplied) alpha by
// default, so the composite is C + (1 - a) bg.
Image ToRgb(const Image& in, const std::array<double, 3>& background, Image* alpha = nullptr);

// A mask or alpha image as one channel: the alpha of an image with alpha (grey + alpha, RGBA),
// else its first channel (a grey mask, or the red of an RGB one).
Image MaskChannel(const Image& in);

// File extensions (lower case, with dot) recognised as images when scanning folders.
bool HasImageExtension(const std::filesystem::path& path);

}  // namespace perf
