// What `perf sfm` (colmap_runner.h) is given, checked before any COLMAP step runs: its options
// (SfmOptions::Check, in sfm_inputs.cc) and the photos in the images folder. Internal to sfm_import/.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace perf::sfm_detail {

// The photos under `images` (recursively, as COLMAP's ImageReader does), as COLMAP names them:
// '/'-separated paths relative to `images`, sorted. Throws InputError when there are none.
std::vector<std::string> ListInputImages(const std::filesystem::path& images);

// Throws InputError naming the photos among `names` (under `images`) whose header cannot be read
// (empty, damaged, not an image, not a regular file), before COLMAP is given any of them.
void CheckPhotosReadable(const std::filesystem::path& images, const std::vector<std::string>& names);

}  // namespace perf::sfm_detail
