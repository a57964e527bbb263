#include "sfm_import/camera_groups.h"

#include <cmath>
#include <map>
#include <tuple>

#include "common/errors.h"
#include "workspace/image_io.h"

namespace perf {

std::vector<CameraGroup> GroupByCamera(const std::filesystem::path& images, const std::vector<std::string>& names) {
  std::vector<CameraGroup> groups;
  std::map<std::string, size_t> index;  // group key -> position in groups
  for (const std::string& name : names) {
    std::string key, description;
    try {
      const CameraTags t = ReadCameraTags(images / name);
      // Focal lengths within 0.05 mm are one zoom setting (EXIF rationals round differently).
      const long focal = std::lround(t.focal_mm * 20);
      key = StrCat(t.width, "x", t.height, "|", t.make, "|", t.model, "|", focal);
      const std::string camera = t.make.empty() && t.model.empty() ? std::string("no EXIF camera")
                                                                   : (t.make.empty() ? t.model : t.make + " " + t.model);
      description = StrCat(t.width, "x", t.height, ", ", camera, t.focal_mm > 0 ? StrCat(", ", t.focal_mm, " mm") : "");
    } catch (const Error&) {
      key = "unreadable|" + name;
      description = "unreadable";
    }
    auto [it, added] = index.emplace(key, groups.size());
    if (added) groups.push_back({description, {}});
    groups[it->second].names.push_back(name);
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
