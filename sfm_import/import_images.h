// The photos of `perf import` (importer.h): how each becomes a workspace image, the names they
// get, and writing them in parallel within the memory there is. Internal to the importer.
#pragma once

#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "workspace/image.h"
#include "workspace/image_io.h"
#include "sfm_import/importer.h"
#include "sfm_import/undistort.h"

namespace perf::import_detail {

// One photo to bring into the workspace.
struct ImageJob {
  std::filesystem::path source;  // the photo on disk
  std::string out_rel;     // workspace-relative output path
  std::string alpha_rel;   // workspace-relative alpha path, empty for none
  const Undistorter* undistorter = nullptr;  // nullptr: no undistortion
  int out_width = 0, out_height = 0;
};

// Workspace images keep the photos' depth: 8/16-bit PNG, float sources as half EXR.
std::string OutputExtension(PixelFormat f);

// Workspace-relative output path for an input name: sanitised into `folder`, with `ext`, and
// made unique ("x.jpg" and "x.png" both become x.png: the second is x-2.png).
std::string ClaimOutputName(const std::string& folder, const std::string& name, const std::string& ext,
                            std::set<std::string>* taken);

// Photos of one size each: the odd one out is named (the size most photos share is the good one).
void CheckOneSize(const std::vector<std::pair<std::filesystem::path, ImageInfo>>& infos, const std::string& group,
                  const std::string& hint);

// Writes every job's images. Nothing may land on an input (checked before the first write);
// photos are processed in parallel, as many at once as fit in the available memory.
// The photo that takes the most memory decoded (image_io.h DecodedBytes), named in the memory check.
struct LargestPhoto {
  int64_t bytes = 0;
  std::filesystem::path path;
  void Consider(const std::filesystem::path& photo, const ImageInfo& info);
};

void RunJobs(const std::vector<ImageJob>& jobs, const ImportOptions& o, const LargestPhoto& largest);

}  // namespace perf::import_detail
