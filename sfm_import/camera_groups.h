// Which photos share a camera: COLMAP refines one set of intrinsics per camera, so
// photos share one only when they agree on size and on what EXIF says of the camera (make, model,
// focal length). Photos from one camera and zoom form one group; a set taken with several cameras,
// zooms or crops gets one camera per group, not one for all (wrong for all but one group) nor one
// per photo (much weaker intrinsics).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "workspace/image_io.h"

namespace perf {

struct CameraGroup {
  std::string description;         // "1600x1200, Canon EOS 5D, 35 mm" or "800x533, no EXIF camera"
  std::vector<std::string> names;  // relative to the images folder, as COLMAP names them
};

// The header tags (ReadCameraTags) of `names`, photos under `images`, read once for both the
// grouping and the capture order (capture_order.h); nullopt where a header cannot be read
// (COLMAP will skip that photo).
std::vector<std::optional<CameraTags>> ReadPhotoTags(const std::filesystem::path& images,
                                                     const std::vector<std::string>& names);

// Groups `names` (with their `tags`, ReadPhotoTags) by size, EXIF make, model and focal length,
// in the order of their first photo. A photo without tags gets a group of its own ("unreadable").
std::vector<CameraGroup> GroupByCamera(const std::vector<std::string>& names,
                                       const std::vector<std::optional<CameraTags>>& tags);

// "3 cameras from the photos' size and EXIF: 28 x 1600x1200, Canon EOS 5D, 35 mm; ..."
std::string DescribeGroups(const std::vector<CameraGroup>& groups);

}  // namespace perf
