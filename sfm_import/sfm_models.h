// The models COLMAP's mapper writes, as `perf sfm` (colmap_runner.h) weighs and keeps them:
// their sizes from the file headers, the photos they left out, and installing the chosen one as
// WORKSPACE/sparse/0. Internal to sfm_import/.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace perf::sfm_detail {

struct ModelCounts {
  int num_images = 0;
  int num_points = 0;
};

// Counts of a binary model in `dir` (from its files' headers), or nullopt if it is not a
// complete one.
std::optional<ModelCounts> ReadModelCounts(const std::filesystem::path& dir);

// The inputs a model left out, when its names can be read.
std::optional<std::vector<std::string>> LeftOut(const std::vector<std::string>& inputs,
                                                const std::filesystem::path& dir);

// Copies `src` to `dst` so that `dst` is either the old model or the complete new one, never a
// mix: copy into a temporary folder beside it, move the old one aside, move the new one in.
void ReplaceDirectory(const std::filesystem::path& src, const std::filesystem::path& dst);

}  // namespace perf::sfm_detail
