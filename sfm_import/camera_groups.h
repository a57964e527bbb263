// Which photos share a camera (issue 19): COLMAP refines one set of intrinsics per camera, so
// photos share one only when they agree on size and on what EXIF says of the camera (make, model,
// focal length). Photos from one camera and zoom form one group; a set taken with several cameras,
// zooms or crops gets one camera per group, not one for all (wrong for all but one group) nor one
// per photo (much weaker intrinsics).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace perf {

struct CameraGroup {
  std::string description;         // "1600x1200, Canon EOS 5D, 35 mm" or "800x533, no EXIF camera"
  std::vector<std::string> names;  // relative to the images folder, as COLMAP names them
};

// Groups `names` (photos under `images`) by size, EXIF make, model and focal length, in the
// order of their first photo. A photo whose header cannot be read gets a group of its own
// ("unreadable"; COLMAP will skip it).
std::vector<CameraGroup> GroupByCamera(const std::filesystem::path& images, const std::vector<std::string>& names);

// "3 cameras from the photos' size and EXIF: 28 x 1600x1200, Canon EOS 5D, 35 mm; ..."
std::string DescribeGroups(const std::vector<CameraGroup>& groups);

}  // namespace perf
