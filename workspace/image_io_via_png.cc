// image_io.h for perf_gpu, which runs on a bare GPU machine without OpenImageIO (bench/README.md
// "perf on a GPU machine"): the workspace's PNG images through libpng (png_io.h), and the image
// pyramid's downscale as an area average (image_ops.h AreaResize) instead of OpenImageIO's
// blackman-harris filter. perf itself links image_io.cc.
#include "common/errors.h"
#include "workspace/image_io.h"
#include "workspace/image_ops.h"
#include "workspace/png_io.h"

namespace fs = std::filesystem;

namespace perf {

ImageInfo ReadImageInfo(const fs::path& path) { return png::ReadInfo(path); }

CameraTags ReadCameraTags(const fs::path& path) {
  throw InputError(path.string(), "", "", "perf_gpu reads no camera tags", "import the photos with perf");
}

Image ReadImage(const fs::path& path, ImageInfo* info) { return png::Read(path, info); }

void WriteImage(const fs::path& path, const Image& image, PixelFormat format) { png::Write(path, image, format); }

Image ResizeImage(const Image& image, int width, int height) {
  PERF_CHECK_MSG(width <= image.width && height <= image.height, "perf_gpu only downscales (", image.width, "x",
                 image.height, " to ", width, "x", height, ")");
  return AreaResize(image, width, height);
}

}  // namespace perf
