// NeRF-synthetic `transforms.json` (Blender convention: camera-to-world matrices, the camera
// looks down -z with +y up; `camera_angle_x` is the horizontal field of view in radians), also
// accepting instant-ngp's explicit intrinsics (fl_x, fl_y, cx, cy, w, h). Poses are converted
// to PERF's camera frame (x right, y down, z forward) on reading.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

namespace perf {

// The largest w and h a transforms.json may give.
inline constexpr int kMaxNerfImageSide = 65536;

struct NerfFrame {
  std::string file_path;                    // as written in the json
  std::filesystem::path image_path;         // resolved, with extension
  Eigen::Matrix<double, 3, 4> world_from_cam;  // PERF camera frame
};

struct NerfTransforms {
  std::optional<double> camera_angle_x, camera_angle_y;
  std::optional<double> fl_x, fl_y, cx, cy;  // pixels (COLMAP-style centre if given)
  std::optional<int> width, height;  // 1 to kMaxNerfImageSide
  std::vector<NerfFrame> frames;

  // Pinhole intrinsics for an image of the given size (PERF pixel convention; the principal
  // point defaults to the image centre). Throws InputError if the json gave no focal length or
  // the intrinsics are not finite for this size.
  void Intrinsics(int w, int h, const std::string& source, double* fx, double* fy, double* px,
                  double* py) const;
};

// Throws InputError naming the file and the field (frames[i].transform_matrix, ...) for bad
// input and IoError if the file cannot be read.
NerfTransforms ReadNerfTransforms(const std::filesystem::path& json_path);
// The json read from `in`: `json_path` names it in messages and is what the frames' file_path
// are resolved against (lexically: no file is opened or looked at).
NerfTransforms ReadNerfTransforms(std::istream& in, const std::filesystem::path& json_path);

}  // namespace perf
