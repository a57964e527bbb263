#include "pipeline/stage_freshness.h"

#include <algorithm>

#include "common/errors.h"
#include "common/inputs.h"
#include "workspace/scene.h"

namespace perf {

namespace fs = std::filesystem;

fs::file_time_type ModTime(const fs::path& p) {
  std::error_code ec;
  const auto t = fs::last_write_time(p, ec);
  return ec ? fs::file_time_type::min() : t;
}

fs::file_time_type NewestInput(const fs::path& p) {
  if (!fs::is_directory(p)) return ModTime(p);
  fs::file_time_type newest = fs::file_time_type::min();
  for (const auto& e : fs::directory_iterator(p)) {
    if (e.is_regular_file()) newest = std::max(newest, ModTime(e.path()));
  }
  return newest;
}

fs::file_time_type NewestUnder(const fs::path& dir) {
  fs::file_time_type newest = fs::file_time_type::min();
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_regular_file(ec)) newest = std::max(newest, ModTime(it->path()));
  }
  return newest;
}

bool NewerThan(const fs::path& output, fs::file_time_type input) {
  return fs::exists(output) && ModTime(output) >= input;
}

std::string ImportChanges(const fs::path& scene_path, const ImportRequest& request) {
  Scene scene;
  try {
    scene = ReadScene(scene_path);
  } catch (const Error& e) {
    return "scene.json cannot be read (" + std::string(e.what()) + ")";
  }
  const SceneSource& src = scene.source;
  if (src.type != (request.colmap ? "colmap" : "nerf") || !RecordedAs(src.path, request.input)) {
    return "scene.json was imported from " + src.path;
  }
  if (request.colmap && !request.images.empty() && !RecordedAs(src.images, request.images)) {
    return "scene.json's photos are from " + src.images;
  }
  if (src.max_size != request.max_size) {
    const auto size = [](int max_size, int downscale) {
      if (max_size < 0) return std::string("a size it does not record (an older perf)");
      return max_size > 0 ? StrCat("at most ", max_size, " px") : downscale > 1 ? StrCat("1/", downscale, " size")
                                                                                : std::string("full size");
    };
    return "scene.json holds photos of " + size(src.max_size, src.downscale) + ", this run asks for " +
           size(request.max_size, 1);
  }
  if (request.keep_bad_poses && AnyExcluded(scene)) return "scene.json leaves out photos that --keep-bad-poses keeps";
  return {};
}

std::vector<std::string> ExcludedByHand(const fs::path& scene_path) {
  std::vector<std::string> names;
  std::error_code ec;
  if (!fs::is_regular_file(scene_path, ec)) return names;
  try {
    for (const SceneImage& im : ReadScene(scene_path).images) {
      if (im.split == Split::kExcluded && im.excluded_because.empty()) names.push_back(im.name);
    }
  } catch (const Error&) {
    // unreadable: nothing to carry
  }
  return names;
}

}  // namespace perf
