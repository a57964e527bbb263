// PNG through libpng itself: the image I/O of perf_gpu (image_io_via_png.cc), which runs on a bare
// GPU machine where OpenImageIO cannot go (bench/README.md "perf on a GPU machine"). Everything
// else reads and writes images through OpenImageIO (image_io.h). Values as OpenImageIO gives
// them: 8- and 16-bit samples over 255 and 65535, no gamma conversion; grey, grey + alpha, RGB,
// RGBA (palette images expanded to RGB or RGBA), colour with alpha associated on read and
// unassociated on write.
#pragma once

#include <filesystem>

#include "workspace/image.h"
#include "workspace/image_io.h"

namespace perf::png {

// The header only. Throws InputError (not a PNG, corrupt, or larger than PERF reads: 65536
// pixels a side, 2^30 in all) naming the file, IoError when it is missing.
ImageInfo ReadInfo(const std::filesystem::path& path);
// The whole image; checks the decoded size against the available memory first.
Image Read(const std::filesystem::path& path, ImageInfo* info = nullptr);
// 8- or 16-bit PNG (format kUInt8 or kUInt16; values clamped to [0, 1] and rounded), written
// atomically; throws IoError naming the file.
void Write(const std::filesystem::path& path, const Image& image, PixelFormat format);

}  // namespace perf::png
