// Shared by the COLMAP model readers and writers (colmap_model.cc, colmap_model_binary.cc,
// colmap_model_text.cc): record limits, hints for messages, and the checks every format makes.
// Internal to sfm_import/.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "common/errors.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_model.h"

namespace perf::colmap::detail {

inline constexpr size_t kMaxNameBytes = 4096;
// Smallest possible records in bytes (layouts in colmap_model.h): a camera with the 3 params of
// SIMPLE_PINHOLE; an image with an empty name and no points.
inline constexpr uint64_t kMinCameraBytes = 4 + 4 + 8 + 8 + 3 * 8;
inline constexpr uint64_t kMinImageBytes = 4 + 4 * 8 + 3 * 8 + 4 + 1 + 8;
inline constexpr uint64_t kPoint2DBytes = 8 + 8 + 8;
inline constexpr uint64_t kMinPoint3DBytes = 8 + 3 * 8 + 3 + 8 + 8;
inline constexpr uint64_t kTrackElementBytes = 4 + 4;
// No real camera has a side this long; larger values are corruption, and later stages would
// allocate width * height pixels.
inline constexpr uint64_t kMaxImageSide = uint64_t{1} << 20;

inline constexpr const char* kModelIdHint =
    "COLMAP model ids are 0-11: SIMPLE_PINHOLE=0, PINHOLE=1, SIMPLE_RADIAL=2, RADIAL=3, "
    "OPENCV=4, OPENCV_FISHEYE=5, FULL_OPENCV=6, FOV=7, SIMPLE_RADIAL_FISHEYE=8, "
    "RADIAL_FISHEYE=9, THIN_PRISM_FISHEYE=10, RAD_TAN_THIN_PRISM_FISHEYE=11";
inline constexpr const char* kModelNameHint =
    "COLMAP models are SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE, "
    "FULL_OPENCV, FOV, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE, THIN_PRISM_FISHEYE, "
    "RAD_TAN_THIN_PRISM_FISHEYE";
inline constexpr const char* kReexportHint =
    "re-export the model from COLMAP (colmap model_converter --output_type BIN) instead of "
    "editing or generating it by hand";
inline constexpr const char* kMismatchHint =
    "the model's files do not belong together; re-export the model from COLMAP (colmap "
    "model_converter) so cameras, images and points3D come from one reconstruction";
inline constexpr const char* kFolderHint =
    "point --colmap at the folder that holds cameras, images and points3D (.bin or .txt), "
    "e.g. sparse/0";

// A possibly hostile string made safe for messages: control bytes escaped, cut short.
std::string Printable(std::string_view s);

// Why an image name cannot be used, or "". Names are relative paths joined to the image folder
// later; control characters (such as the newline that would break images.txt) are never part
// of a real file name.
std::string NameProblem(std::string_view name);

inline std::string ListValues(const auto& values) {
  std::string s;
  for (const double v : values) s += StrCat(s.empty() ? "" : " ", v);
  return s;
}

inline bool AllFinite(const auto& values) {
  for (const double v : values) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

// Writers take a model built in memory, so inconsistencies there are our bugs, not input errors.
const CameraModelInfo& ModelForWriting(const Camera& cam);
void CheckNameForWriting(const Image& image);

}  // namespace perf::colmap::detail
