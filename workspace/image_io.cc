#include "workspace/image_io.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <array>
#include <cctype>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/system_memory.h"

namespace fs = std::filesystem;
namespace OIIO = OIIO_NAMESPACE;

namespace perf {
namespace {

// PNG writer settings (libpng's values): zlib level 1, and the Sub filter on every row.
constexpr int kPngCompressionLevel = 1;
constexpr int kPngFilterSub = 0x10;  // PNG_FILTER_SUB

// PERF reads, writes and resizes images from its own parallel loops; OIIO's thread pool inside
// each call only contends with them (lego's mask export took 1.3x as long with it): off, once.
void SingleThreadedOiio() {
  static const bool set = OIIO::attribute("threads", 1);
  (void)set;
}

PixelFormat FromTypeDesc(const OIIO::TypeDesc& t) {
  if (t == OIIO::TypeDesc::UINT8 || t == OIIO::TypeDesc::INT8) return PixelFormat::kUInt8;
  if (t == OIIO::TypeDesc::UINT16 || t == OIIO::TypeDesc::INT16) return PixelFormat::kUInt16;
  if (t == OIIO::TypeDesc::HALF) return PixelFormat::kHalf;
  return PixelFormat::kFloat;
}

OIIO::TypeDesc ToTypeDesc(PixelFormat f) {
  switch (f) {
    case PixelFormat::kUInt8: return OIIO::TypeDesc::UINT8;
    case PixelFormat::kUInt16: return OIIO::TypeDesc::UINT16;
    case PixelFormat::kHalf: return OIIO::TypeDesc::HALF;
    case PixelFormat::kFloat: return OIIO::TypeDesc::FLOAT;
  }
  return OIIO::TypeDesc::FLOAT;
}

std::unique_ptr<OIIO::ImageInput> OpenInput(const fs::path& path) {
  SingleThreadedOiio();
  if (!fs::exists(path)) {
    throw IoError(path.string(), "image file not found", "check the --images folder and the names in the model");
  }
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) {
    throw InputError(path.string(), "", "", "not a readable image (" + OIIO::geterror() + ")",
                     "re-export it as JPEG, PNG, TIFF or EXR, or remove it from the model");
  }
  return in;
}

// Sizes read from a header are bounded before anything is allocated: 65536 pixels a side and
// 2^30 pixels in all (OpenEXR's and libpng's own practical limits are of that order).
void CheckDimensions(const fs::path& path, const OIIO::ImageSpec& spec) {
  const std::string size = StrCat(spec.width, "x", spec.height, "x", spec.nchannels);
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0) {
    throw InputError(path.string(), "size", size, "image has no pixels", "re-export it");
  }
  constexpr int64_t kMaxSide = 65536, kMaxPixels = int64_t{1} << 30;
  if (spec.width > kMaxSide || spec.height > kMaxSide || int64_t{spec.width} * spec.height > kMaxPixels) {
    throw InputError(path.string(), "size", size, "larger than PERF reads (65536 pixels a side, 2^30 pixels in all)",
                     "downscale the photo first (e.g. oiiotool --resize 50%)");
  }
}

}  // namespace

ImageInfo ReadImageInfo(const fs::path& path) {
  CheckRegularFile(path);
  auto in = OpenInput(path);
  const OIIO::ImageSpec& spec = in->spec();
  CheckDimensions(path, spec);
  ImageInfo info{spec.width, spec.height, spec.nchannels, FromTypeDesc(spec.format)};
  in->close();
  return info;
}

CameraTags ReadCameraTags(const fs::path& path) {
  CheckRegularFile(path);
  auto in = OpenInput(path);
  const OIIO::ImageSpec& spec = in->spec();
  CameraTags t;
  t.width = spec.width;
  t.height = spec.height;
  t.make = spec.get_string_attribute("Make");
  t.model = spec.get_string_attribute("Model");
  t.focal_mm = spec.get_float_attribute("Exif:FocalLength", 0.f);
  t.time = spec.get_string_attribute("Exif:DateTimeOriginal");
  in->close();
  return t;
}

Image ReadImage(const fs::path& path, ImageInfo* info) {
  CheckRegularFile(path);
  auto in = OpenInput(path);
  const OIIO::ImageSpec spec = in->spec();
  CheckDimensions(path, spec);
  // Grey, grey+alpha, RGB and RGBA are kept; extra channels beyond 4 are dropped.
  const int channels = std::min(spec.nchannels, 4);
  const ImageInfo read{spec.width, spec.height, channels, FromTypeDesc(spec.format)};
  CheckFitsInMemory(DecodedBytes(read), StrCat("decoding ", path.string(), " (", spec.width, "x", spec.height, ")"),
                    "downscale the photos first, or use fewer threads (-j)");
  Image image(spec.width, spec.height, channels);
  // Reads the first subimage/miplevel as stored: no EXIF reorientation (COLMAP does none).
  // Decoders report truncated or corrupt data as errors or warnings; either refuses the image
  // (a truncated JPEG otherwise decodes as grey without a word).
  const bool ok = in->read_image(0, 0, 0, channels, OIIO::TypeDesc::FLOAT, image.pixels.data());
  in->close();  // first: a decoder may report more while closing
  const std::string problem = in->has_error() ? in->geterror() : std::string();
  if (!ok || !problem.empty()) {
    throw InputError(path.string(), "pixels", "", "cannot decode the image" + (problem.empty() ? "" : " (" + problem + ")"),
                     "the file may be truncated or corrupt; re-export it");
  }
  if (info) *info = read;
  return image;
}

namespace {

// Encodes `image` as the format of `path`'s extension, through `out`; throws IoError naming
// `path`. `file` is where the encoder writes (a temporary, or `path` itself with an ioproxy).
void Encode(OIIO::ImageOutput& out, const fs::path& path, const std::string& file, const Image& image,
            PixelFormat format) {
  OIIO::ImageSpec spec(image.width, image.height, image.channels, ToTypeDesc(format));
  if (image.channels == 4) spec.alpha_channel = 3;
  if (image.channels == 2) spec.alpha_channel = 1;
  // zlib level 1 with the Sub filter: 2x faster than libpng's default (level 6, each row's best
  // filter tried), and on lego's masks and cut-outs 4 % smaller in all (docs/tuning.md).
  spec.attribute("png:compressionLevel", kPngCompressionLevel);
  spec.attribute("png:filter", kPngFilterSub);
  if (!out.open(file, spec)) {
    throw IoError(path.string(), "cannot create the image file (" + out.geterror() + ")",
                  "check that the folder is writable");
  }
  // OIIO clamps and quantises float to integer formats on write.
  const bool ok = out.write_image(OIIO::TypeDesc::FLOAT, image.pixels.data());
  const bool closed = out.close();
  if (!ok || !closed) {
    throw IoError(path.string(), "writing the image failed (" + out.geterror() + ")",
                  "check the free disk space and that the folder is writable");
  }
}

}  // namespace

void WriteImage(const fs::path& path, const Image& image, PixelFormat format) {
  PERF_CHECK(!image.empty());
  auto out = OIIO::ImageOutput::create(path.string());
  if (!out) throw IoError(path.string(), "no image writer for this extension (" + OIIO::geterror() + ")");
  SingleThreadedOiio();
  // The formats PERF writes (PNG, JPEG, EXR) are encoded in memory, then written with checked
  // calls: OIIO's file writers do not all report a full disk. (OIIO 2.4's TIFF writer claims an
  // ioproxy but fails on it, so other formats go through a temporary file.)
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  const bool in_memory = ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".exr";
  if (in_memory && out->supports("ioproxy")) {
    std::vector<unsigned char> bytes;
    OIIO::Filesystem::IOVecOutput proxy(bytes);
    out->set_ioproxy(&proxy);
    Encode(*out, path, path.string(), image, format);
    WriteFileAtomically(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
    return;
  }
  WriteAtomically(path, [&](const fs::path& tmp) { Encode(*out, path, tmp.string(), image, format); });
}

Image ResizeImage(const Image& image, int width, int height) {
  SingleThreadedOiio();
  PERF_CHECK(width > 0 && height > 0 && !image.empty());
  if (width == image.width && height == image.height) return image;
  OIIO::ImageSpec src_spec(image.width, image.height, image.channels, OIIO::TypeDesc::FLOAT);
  OIIO::ImageBuf src(src_spec, const_cast<float*>(image.pixels.data()));
  OIIO::ImageSpec dst_spec(width, height, image.channels, OIIO::TypeDesc::FLOAT);
  Image out(width, height, image.channels);
  OIIO::ImageBuf dst(dst_spec, out.pixels.data());
  // An empty filter name lets OIIO choose: blackman-harris for minification, which is what a
  // photographer's downscale would use (no aliasing, little blur).
  if (!OIIO::ImageBufAlgo::resize(dst, src, "", 0.f, OIIO::ROI::All(), 0)) {
    throw InternalError("OpenImageIO resize failed: " + dst.geterror());
  }
  return out;
}

}  // namespace perf
