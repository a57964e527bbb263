#include "sfm_import/camera_groups.h"

#include <cmath>
#include <map>
#include <tuple>

#include "common/errors.h"
#include "workspace/image_io.h"

namespace perf {

std::vector<std::optional<CameraTags>> ReadPhotoTags(const std::filesystem::path& images,
                                                     const std::vector<std::string>& names) {
  std::vector<std::optional<CameraTags>> tags;
  tags.reserve(names.size());
  for (const std::string& name : names) {
    try {
      tags.push_back(ReadCameraTags(images / name));
    } catch (const Error&) {
      tags.push_back(std::nullopt);
    }
  }
  return tags;
}

std::vector<CameraGroup> GroupByCamera(const std::vector<std::string>& names,
                                       const std::vector<std::optional<CameraTags>>& tags) {
  PERF_CHECK(tags.size() == names.size());
  std::vector<CameraGroup> groups;
  std::map<std::string, size_t> index;  // group key -> position in groups
  for (size_t i = 0; i < names.size(); ++i) {
    std::string key = "unreadable|" + names[i], description = "unreadable";
    if (const std::optional<CameraTags>& t = tags[i]) {
      // Focal lengths within 0.05 mm are one zoom setting (EXIF rationals round differently).
      const long focal = std::lround(t->focal_mm * 20);
      key = StrCat(t->width, "x", t->height, "|", t->make, "|", t->model, "|", focal);
      const std::string camera = t->make.empty() && t->model.empty()
                                     ? std::string("no EXIF camera")
                                     : (t->make.empty() ? t->model : t->make + " " + t->model);
      description = StrCat(t->width, "x", t->height, ", ", camera, t->focal_mm > 0 ? StrCat(", ", t->focal_mm, " mm") : "");
    }
    auto [it, added] = index.emplace(key, groups.size());
    if (added) groups.push_back({description, {}});
    groups[it->second].names.push_back(names[i]);
  }
  return groups;
}

std::string DescribeGroups(const std::vector<CameraGroup>& groups) {
  std::string out = StrCat(groups.size(), groups.size() == 1 ? " camera" : " cameras", " from the photos' size and EXIF: ");
  for (size_t i = 0; i < groups.size(); ++i) {
    out += StrCat(i ? "; " : "", groups[i].names.size(), " x ", groups[i].description);
  }
  return out;
}

}  // namespace perf
