// When `perf run` may skip a stage: its outputs are newer than its inputs (file times) and were
// made with the settings this run asks for. The reconstruction's own settings are compared by
// recon/settings.json (recon_cuda/run/run_settings.h), sfm's photos by colmap/inputs.json
// (colmap_runner.cc); here, the times and the import's source.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace perf {

// A file's modification time; the oldest time when it cannot be read.
std::filesystem::file_time_type ModTime(const std::filesystem::path& p);
// The newest file directly in `p` (a COLMAP model folder), or the file itself.
std::filesystem::file_time_type NewestInput(const std::filesystem::path& p);
// The newest file under `dir`, subfolders too (the photos, which COLMAP names with their
// subfolders); the oldest time when there is no folder.
std::filesystem::file_time_type NewestUnder(const std::filesystem::path& dir);
// Whether `output` exists and is not older than `input`.
bool NewerThan(const std::filesystem::path& output, std::filesystem::file_time_type input);

// What `perf run` would import.
struct ImportRequest {
  bool colmap = true;                 // else a NeRF transforms.json
  std::filesystem::path input;        // the COLMAP model folder or the json
  std::filesystem::path images;       // COLMAP: the photos (empty: not given)
  int max_size = 0;                   // the longest side asked for (0: full size)
  bool keep_bad_poses = false;
};

// Why the workspace's scene.json is not what `request` would import: another source, photo folder,
// photo size or bad-pose rule; empty when it is. An unreadable scene.json is imported again.
std::string ImportChanges(const std::filesystem::path& scene_path, const ImportRequest& request);

// The photos scene.json leaves out by hand ("split": "excluded" with no reason recorded, as the
// photo-fit warning suggests); a new import does not keep them. Empty without a readable scene.json.
std::vector<std::string> ExcludedByHand(const std::filesystem::path& scene_path);

}  // namespace perf
