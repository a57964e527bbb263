#include "workspace/png_io.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/system_memory.h"

namespace fs = std::filesystem;

namespace perf::png {
namespace {

constexpr int64_t kMaxSide = 65536, kMaxPixels = int64_t{1} << 30;  // as image_io.cc

// libpng reports errors by longjmp to the png_jmpbuf of the struct: every call that may fail
// runs inside a function whose frame holds no object with a destructor, and a failure becomes
// `message` (libpng's words) for the C++ caller to throw.
struct Reader {
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::FILE* file = nullptr;
  char message[256] = "";
  ~Reader() {
    png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
    if (file) std::fclose(file);
  }
};

void OnError(png_structp png, png_const_charp msg) {
  auto* message = static_cast<char*>(png_get_error_ptr(png));
  std::snprintf(message, 256, "%s", msg);
  png_longjmp(png, 1);
}
void OnWarning(png_structp, png_const_charp) {}

// Opens and reads the header with the expanding transforms set (palette and low-bit grey to 8
// bits, tRNS to alpha, 16-bit to host order): false on a libpng error (r.message).
bool ReadHeader(Reader& r, const fs::path& path) {
  r.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, r.message, OnError, OnWarning);
  if (!r.png) return false;
  r.info = png_create_info_struct(r.png);
  if (!r.info) return false;
  if (setjmp(png_jmpbuf(r.png))) return false;
  png_set_user_limits(r.png, kMaxSide, kMaxSide);
  png_init_io(r.png, r.file);
  png_read_info(r.png, r.info);
  png_set_expand(r.png);
  if (png_get_bit_depth(r.png, r.info) == 16) png_set_swap(r.png);
  png_read_update_info(r.png, r.info);
  return true;
}

bool ReadRows(Reader& r, png_bytep* rows) {
  if (setjmp(png_jmpbuf(r.png))) return false;
  png_read_image(r.png, rows);
  png_read_end(r.png, nullptr);
  return true;
}

ImageInfo Open(Reader& r, const fs::path& path) {
  CheckRegularFile(path);
  r.file = std::fopen(path.c_str(), "rb");
  if (!r.file) throw IoError(path.string(), "cannot open the image file", "check that it is readable");
  png_byte signature[8];
  if (std::fread(signature, 1, 8, r.file) != 8 || png_sig_cmp(signature, 0, 8) != 0) {
    throw InputError(path.string(), "", "", "not a PNG file", "perf_gpu reads the workspace's PNG images only");
  }
  std::rewind(r.file);
  if (!ReadHeader(r, path)) {
    throw InputError(path.string(), "header", "", StrCat("not a readable PNG (", r.message, ")"), "re-export it");
  }
  ImageInfo info;
  info.width = static_cast<int>(png_get_image_width(r.png, r.info));
  info.height = static_cast<int>(png_get_image_height(r.png, r.info));
  info.channels = png_get_channels(r.png, r.info);
  info.format = png_get_bit_depth(r.png, r.info) == 16 ? PixelFormat::kUInt16 : PixelFormat::kUInt8;
  if (info.width <= 0 || info.height <= 0 || int64_t{info.width} * info.height > kMaxPixels) {
    throw InputError(path.string(), "size", StrCat(info.width, "x", info.height),
                     "larger than PERF reads (65536 pixels a side, 2^30 pixels in all)", "downscale it first");
  }
  return info;
}

}  // namespace

ImageInfo ReadInfo(const fs::path& path) {
  Reader r;
  return Open(r, path);
}

Image Read(const fs::path& path, ImageInfo* info_out) {
  Reader r;
  const ImageInfo info = Open(r, path);
  CheckFitsInMemory(DecodedBytes(info) + int64_t{info.width} * info.height * info.channels * 2,
                    StrCat("decoding ", path.string(), " (", info.width, "x", info.height, ")"),
                    "downscale the photos first, or use fewer threads (-j)");
  const bool wide = info.format == PixelFormat::kUInt16;
  const size_t row_bytes = png_get_rowbytes(r.png, r.info);
  std::vector<png_byte> bytes(row_bytes * info.height);
  std::vector<png_bytep> rows(info.height);
  for (int y = 0; y < info.height; ++y) rows[y] = bytes.data() + y * row_bytes;
  if (!ReadRows(r, rows.data())) {
    throw InputError(path.string(), "pixels", "", StrCat("cannot decode the image (", r.message, ")"),
                     "the file may be truncated or corrupt; re-export it");
  }
  // Colour with alpha comes back associated (premultiplied), as OpenImageIO gives it (image_io.h):
  // in the stored integers, c = c a / max, rounded down, as OpenImageIO's PNG reader does for a
  // file of gamma 1. With a gamma chunk it associates in linear light instead; workspace images
  // have no alpha (their alpha is a grey image of its own), so such files are refused.
  if (info.channels == 2 || info.channels == 4) {
    double gamma = 0;
    if (png_get_valid(r.png, r.info, PNG_INFO_sRGB) ||
        (png_get_gAMA(r.png, r.info, &gamma) && std::abs(gamma - 1.0) > 1e-3)) {
      throw InputError(path.string(), "gamma", "", "perf_gpu reads PNG with alpha only without a gamma or sRGB chunk",
                       "import the photos with perf (it writes colour and alpha apart)");
    }
    const int a = info.channels - 1;
    const auto associate = [&](auto* v, uint32_t max) {
      for (int64_t p = 0; p < int64_t{info.width} * info.height; ++p, v += info.channels)
        for (int c = 0; c < a; ++c) v[c] = static_cast<uint32_t>(v[c]) * v[a] / max;
    };
    if (wide) associate(reinterpret_cast<uint16_t*>(bytes.data()), 65535u);
    else associate(bytes.data(), 255u);
  }
  Image image(info.width, info.height, info.channels);
  const size_t n = image.pixels.size();
  // As OpenImageIO converts: times the float reciprocal (not a division: they differ in the last
  // bit for some values), so that perf_gpu trains on the very floats perf does.
  if (wide) {
    const auto* v = reinterpret_cast<const uint16_t*>(bytes.data());
    for (size_t i = 0; i < n; ++i) image.pixels[i] = static_cast<float>(v[i]) * (1.f / 65535.f);
  } else {
    for (size_t i = 0; i < n; ++i) image.pixels[i] = static_cast<float>(bytes[i]) * (1.f / 255.f);
  }
  if (info_out) *info_out = info;
  return image;
}

namespace {

struct Writer {
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::string* out = nullptr;
  char message[256] = "";
  ~Writer() { png_destroy_write_struct(&png, info ? &info : nullptr); }
};

void Append(png_structp png, png_bytep data, png_size_t length) {
  static_cast<std::string*>(png_get_io_ptr(png))->append(reinterpret_cast<const char*>(data), length);
}
void Flush(png_structp) {}

bool Encode(Writer& w, int width, int height, int channels, int depth, png_bytep* rows) {
  w.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, w.message, OnError, OnWarning);
  if (!w.png) return false;
  w.info = png_create_info_struct(w.png);
  if (!w.info) return false;
  if (setjmp(png_jmpbuf(w.png))) return false;
  static const int kColour[5] = {0, PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_GRAY_ALPHA, PNG_COLOR_TYPE_RGB,
                                 PNG_COLOR_TYPE_RGB_ALPHA};
  png_set_write_fn(w.png, w.out, Append, Flush);
  png_set_IHDR(w.png, w.info, width, height, depth, kColour[channels], PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(w.png, w.info);
  if (depth == 16) png_set_swap(w.png);
  png_write_image(w.png, rows);
  png_write_end(w.png, nullptr);
  return true;
}

}  // namespace

void Write(const fs::path& path, const Image& image, PixelFormat format) {
  PERF_CHECK(!image.empty() && image.channels >= 1 && image.channels <= 4);
  if (format != PixelFormat::kUInt8 && format != PixelFormat::kUInt16) {
    throw InputError(path.string(), "format", "", "perf_gpu writes 8- and 16-bit PNG only",
                     "write float images with perf on a machine with OpenImageIO");
  }
  const bool wide = format == PixelFormat::kUInt16;
  const float top = wide ? 65535.f : 255.f;
  const size_t n = image.pixels.size(), sample = wide ? 2 : 1;
  std::vector<png_byte> bytes(n * sample);
  for (size_t i = 0; i < n; ++i) {
    const float v = image.pixels[i];
    // Clamped (NaN to 0) and rounded in float, as OpenImageIO quantises.
    const auto q = static_cast<uint32_t>((v > 0.f ? (v < 1.f ? v : 1.f) : 0.f) * top + 0.5f);
    if (wide) reinterpret_cast<uint16_t*>(bytes.data())[i] = static_cast<uint16_t>(q);
    else bytes[i] = static_cast<png_byte>(q);
  }
  // Associated colour is stored unassociated: c = min(max, c max / a) in the quantised integers
  // where a > 0, as OpenImageIO's PNG writer does.
  if (image.channels == 2 || image.channels == 4) {
    const int a = image.channels - 1;
    const auto deassociate = [&](auto* v, uint32_t max) {
      for (int64_t p = 0; p < int64_t{image.width} * image.height; ++p, v += image.channels) {
        if (v[a] == 0) continue;
        for (int c = 0; c < a; ++c) v[c] = std::min(max, static_cast<uint32_t>(v[c]) * max / v[a]);
      }
    };
    if (wide) deassociate(reinterpret_cast<uint16_t*>(bytes.data()), 65535u);
    else deassociate(bytes.data(), 255u);
  }
  const size_t row_bytes = static_cast<size_t>(image.width) * image.channels * sample;
  std::vector<png_bytep> rows(image.height);
  for (int y = 0; y < image.height; ++y) rows[y] = bytes.data() + y * row_bytes;
  std::string encoded;
  Writer w;
  w.out = &encoded;
  if (!Encode(w, image.width, image.height, image.channels, wide ? 16 : 8, rows.data())) {
    throw IoError(path.string(), StrCat("encoding the PNG failed (", w.message, ")"), "");
  }
  WriteFileAtomically(path, encoded);
}

}  // namespace perf::png
