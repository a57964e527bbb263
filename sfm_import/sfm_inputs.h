// What `perf sfm` (colmap_runner.h) is given, checked before any COLMAP step runs: its options
// (SfmOptions::Check, in sfm_inputs.cc), the photos in the images folder, and the record of what
// the model at sparse/0 was made from. Internal to sfm_import/.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "sfm_import/colmap_runner.h"

namespace perf::sfm_detail {

// The photos under `images` (recursively, as COLMAP's ImageReader does), as COLMAP names them:
// '/'-separated paths relative to `images`, sorted. Throws InputError when there are none.
std::vector<std::string> ListInputImages(const std::filesystem::path& images);

// Throws InputError naming the photos among `names` (under `images`) whose header cannot be read
// (empty, damaged, not an image, not a regular file), before COLMAP is given any of them.
void CheckPhotosReadable(const std::filesystem::path& images, const std::vector<std::string>& names);

// "a.jpg, b.jpg, c.jpg and 4 more"
std::string NameList(const std::vector<std::string>& names, size_t shown = 8);

// What the model at sparse/0 was made from: WORKSPACE/colmap/inputs.json, the images folder and
// its photos as COLMAP named them, written when a run installs its model (a run that fails
// before leaves the model and its record as they were).
std::filesystem::path InputsRecordPath(const SfmOptions& options);
void WriteInputsRecord(const SfmOptions& options, const std::vector<std::string>& inputs);

// How the recorded inputs differ from `inputs` ("made from other photos (1 added since: c.jpg)");
// empty when they do not, or when nothing was recorded (a model of an older perf, or one put there
// by hand: kept).
std::string InputsChanged(const SfmOptions& options, const std::vector<std::string>& inputs);

}  // namespace perf::sfm_detail
