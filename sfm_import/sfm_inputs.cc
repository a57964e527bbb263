#include "sfm_import/sfm_inputs.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <iterator>
#include <nlohmann/json.hpp>
#include <set>
#include <string_view>
#include <system_error>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/inputs.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_runner.h"
#include "workspace/image_io.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

constexpr const char* kCommandLine = "command line";

// What COLMAP (through FreeImage) reads in practice. Counting by extension, not by decoding,
// keeps this cheap on large folders; COLMAP itself skips files it cannot decode.
bool LooksLikeImage(const fs::path& path) {
  static constexpr std::array<std::string_view, 11> kExtensions = {
      ".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".ppm", ".pgm", ".webp", ".jp2", ".exr"};
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return std::find(kExtensions.begin(), kExtensions.end(), ext) != kExtensions.end();
}

}  // namespace

namespace sfm_detail {

std::vector<std::string> ListInputImages(const fs::path& images) {
  std::error_code ec;
  if (!fs::exists(images, ec)) {
    throw InputError(kCommandLine, "--images", images.string(), "the images folder does not exist",
                     "pass the folder that holds your photos");
  }
  if (!fs::is_directory(images, ec)) {
    throw InputError(kCommandLine, "--images", images.string(), "not a folder",
                     "pass the folder that holds your photos, not a single file");
  }
  std::vector<std::string> names;
  fs::recursive_directory_iterator it(images, fs::directory_options::skip_permission_denied, ec);
  if (ec) {
    throw IoError(images.string(), "cannot list the images folder: " + ec.message(),
                  "check its permissions");
  }
  for (const fs::recursive_directory_iterator end; it != end; it.increment(ec)) {
    if (ec) {
      throw IoError(images.string(), "cannot list the images folder: " + ec.message(),
                    "check its permissions");
    }
    if (it->is_regular_file(ec) && LooksLikeImage(it->path())) {
      names.push_back(it->path().lexically_relative(images).generic_string());
    }
  }
  if (names.empty()) {
    throw InputError(kCommandLine, "--images", images.string(),
                     "the folder holds no images (looked for .jpg, .jpeg, .png, .tif, .tiff, .bmp, "
                     ".ppm, .pgm, .webp, .jp2, .exr, also in sub-folders)",
                     "put your photos in it or pass the folder that holds them");
  }
  std::sort(names.begin(), names.end());
  return names;
}

void CheckPhotosReadable(const fs::path& images, const std::vector<std::string>& names) {
  std::vector<std::string> bad;
  std::string first_problem;
  for (const std::string& name : names) {
    try {
      ReadImageInfo(images / name);
    } catch (const Error& e) {
      if (bad.empty()) first_problem = e.what();
      bad.push_back(name);
    }
  }
  if (bad.empty()) return;
  std::string listed;
  for (size_t i = 0; i < bad.size() && i < 5; ++i) listed += StrCat(i ? ", " : "", bad[i]);
  if (bad.size() > 5) listed += StrCat(" and ", bad.size() - 5, " more");
  throw InputError(images.string(), "", "",
                   StrCat(bad.size(), " of the ", names.size(), " photos cannot be read: ", listed, " (the first: ",
                          first_problem, ")"),
                   "remove them from the folder (or replace them with the photos), then run again");
}

// "a.jpg, b.jpg, c.jpg and 4 more"
std::string NameList(const std::vector<std::string>& names, size_t shown) {
  std::string list;
  for (size_t i = 0; i < names.size() && i < shown; ++i) list += (i ? ", " : "") + names[i];
  if (names.size() > shown) list += StrCat(" and ", names.size() - shown, " more");
  return list;
}

fs::path InputsRecordPath(const SfmOptions& options) { return options.workspace / "colmap" / "inputs.json"; }

void WriteInputsRecord(const SfmOptions& options, const std::vector<std::string>& inputs) {
  const nlohmann::json record = {{"images", RecordedPath(options.images)}, {"photos", inputs}};
  WriteFileAtomically(InputsRecordPath(options), record.dump(1) + "\n");
}

std::string InputsChanged(const SfmOptions& options, const std::vector<std::string>& inputs) {
  std::error_code ec;
  if (!fs::is_regular_file(InputsRecordPath(options), ec)) return {};
  const nlohmann::json before = nlohmann::json::parse(ReadFileToString(InputsRecordPath(options)), nullptr, false);
  if (!before.is_object() || !before.contains("photos") || !before["photos"].is_array()) return {};
  const std::string folder = before.value("images", "");
  if (!RecordedAs(folder, options.images)) return "made from the photos in " + folder;
  std::set<std::string> old_names, new_names(inputs.begin(), inputs.end());
  for (const auto& n : before["photos"]) {
    if (n.is_string()) old_names.insert(n.get<std::string>());
  }
  std::vector<std::string> added, gone;
  std::set_difference(new_names.begin(), new_names.end(), old_names.begin(), old_names.end(), std::back_inserter(added));
  std::set_difference(old_names.begin(), old_names.end(), new_names.begin(), new_names.end(), std::back_inserter(gone));
  std::string why;
  if (!added.empty()) why = StrCat(added.size(), " added since: ", NameList(added));
  if (!gone.empty()) why += StrCat(why.empty() ? "" : "; ", gone.size(), " gone: ", NameList(gone));
  return why.empty() ? why : "made from other photos (" + why + ")";
}

}  // namespace sfm_detail

// ----------------------------------------------------------------------------------------------

void SfmOptions::Check() const {
  if (images.empty()) {
    throw InputError(kCommandLine, "--images", "", "no images folder given",
                     "pass the folder that holds your photos");
  }
  if (workspace.empty()) {
    throw InputError(kCommandLine, "--workspace", "", "no workspace folder given",
                     "pass a folder for COLMAP's files and the sparse model");
  }
  if (colmap_binary.empty()) {
    throw InputError(kCommandLine, "--colmap-binary", "", "empty",
                     "pass `colmap` (looked up on PATH) or the path of the binary");
  }
  // Only the models perf import can undistort: a model of another one could not be imported.
  const colmap::CameraModelInfo* model = colmap::FindCameraModel(camera_model);
  if (model == nullptr || !model->supported) {
    throw InputError(kCommandLine, "--camera-model", camera_model,
                     model == nullptr ? "not a COLMAP camera model" : "a camera model perf import cannot undistort",
                     "use one of SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV, "
                     "OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE (upper case)");
  }
  if (matcher != "auto" && matcher != "exhaustive" && matcher != "sequential") {
    throw InputError(kCommandLine, "--matcher", matcher, "unknown matcher",
                     "use auto, exhaustive or sequential");
  }
  auto check_at_least = [](const char* field, int value, int min, const char* hint) {
    if (value < min) {
      throw InputError(kCommandLine, field, std::to_string(value), StrCat("must be at least ", min),
                       hint);
    }
  };
  check_at_least("--exhaustive-max", exhaustive_max_images, 0,
                 "0 always uses the sequential matcher in auto mode");
  check_at_least("--overlap", sequential_overlap, 1,
                 "how many following photos each photo is matched with, e.g. 10");
  check_at_least("--max-image-size", max_image_size, 1, "longest side in pixels, e.g. 1600");
  check_at_least("--max-features", max_num_features, 1, "features per image, e.g. 8192");
  check_at_least("--min-pose-inliers", min_pose_inliers, 0, "inlier matches a photo's placement needs, e.g. 100 (0: from --max-features)");
  if (!(min_pose_inlier_ratio > 0 && min_pose_inlier_ratio < 1)) {
    throw InputError(kCommandLine, "--min-pose-inlier-ratio", StrCat(min_pose_inlier_ratio), "must be in (0, 1)",
                     "the fraction of a photo's matches that must be inliers, e.g. 0.4");
  }
  if (!(idle_timeout_seconds > 0) || !std::isfinite(idle_timeout_seconds)) {
    throw InputError(kCommandLine, "--colmap-idle-timeout", StrCat(idle_timeout_seconds),
                     "must be a positive number of seconds", "e.g. 1800 (30 minutes)");
  }
  check_at_least("--min-registered", min_registered_images, 2,
                 "a model needs at least two images");
  if (num_threads != -1 && num_threads < 1) {
    throw InputError(kCommandLine, "-j", std::to_string(num_threads),
                     "must be -1 (all cores) or at least 1");
  }
}

}  // namespace perf
