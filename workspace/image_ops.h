// Image operations that need no codec library: the box (area-average) downscale that perf_gpu's
// image pyramid uses where OpenImageIO's filtered resize (image_io.h ResizeImage) is not there.
#pragma once

#include "workspace/image.h"

namespace perf {

// Downscales to exactly `width` x `height` (each at most the image's), every output pixel the
// area-weighted mean of the source pixels it covers.
Image AreaResize(const Image& image, int width, int height);

}  // namespace perf
