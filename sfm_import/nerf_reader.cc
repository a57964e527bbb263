#include "sfm_import/nerf_reader.h"

#include <Eigen/Dense>
#include <cmath>
#include <fstream>
#include <sstream>
#include <nlohmann/json.hpp>
#include <utility>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "workspace/image_io.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace perf {
namespace {

// `v` as JSON for a message: nested at most `depth` levels and cut at 80 characters, so that a
// value is quoted without walking (recursively) arbitrarily deep input.
std::string Shown(const json& v, int depth = 2) {
  std::string s;
  if (v.is_array()) {
    s = "[";
    for (size_t i = 0; i < v.size() && s.size() < 80; ++i) {
      s += (i ? "," : "") + (depth > 0 ? Shown(v[i], depth - 1) : std::string("..."));
    }
    s += "]";
  } else if (v.is_object()) {
    s = "{...}";
  } else {
    s = v.dump();
  }
  return s.size() > 80 ? s.substr(0, 77) + "..." : s;
}

std::optional<double> OptNumber(const json& j, const char* key, const std::string& source) {
  if (!j.contains(key)) return std::nullopt;
  const json& v = j[key];
  if (!v.is_number() || !std::isfinite(v.get<double>())) {
    throw InputError(source, key, Shown(v), "expected a finite number");
  }
  return v.get<double>();
}

// fl_x, fl_y: a focal length in pixels.
std::optional<double> OptFocal(const json& j, const char* key, const std::string& source) {
  const std::optional<double> v = OptNumber(j, key, source);
  if (v && !(*v > 0)) {
    throw InputError(source, key, StrCat(*v), "a focal length must be positive (pixels)",
                     "write the focal length in pixels, or give camera_angle_x (radians) instead");
  }
  return v;
}

// camera_angle_x, camera_angle_y: a field of view in radians.
std::optional<double> OptAngle(const json& j, const char* key, const std::string& source) {
  const std::optional<double> v = OptNumber(j, key, source);
  if (v && !(*v > 0 && *v < M_PI)) {
    throw InputError(source, key, StrCat(*v), "must be a field of view in radians, between 0 and pi",
                     "write the field of view in radians (not degrees)");
  }
  return v;
}

// w, h: an image side in pixels.
std::optional<int> OptSide(const json& j, const char* key, const std::string& source) {
  const std::optional<double> v = OptNumber(j, key, source);
  if (!v) return std::nullopt;
  if (!(*v >= 1 && *v <= kMaxNerfImageSide && *v == std::floor(*v))) {
    throw InputError(source, key, StrCat(*v), StrCat("must be a whole number of pixels, 1 to ", kMaxNerfImageSide),
                     "write the image size in pixels, or leave w and h out");
  }
  return static_cast<int>(*v);
}

void ReadIntrinsics(const json& j, const std::string& source, NerfTransforms* t) {
  t->camera_angle_x = OptAngle(j, "camera_angle_x", source);
  t->camera_angle_y = OptAngle(j, "camera_angle_y", source);
  t->fl_x = OptFocal(j, "fl_x", source);
  t->fl_y = OptFocal(j, "fl_y", source);
  t->cx = OptNumber(j, "cx", source);
  t->cy = OptNumber(j, "cy", source);
  t->width = OptSide(j, "w", source);
  t->height = OptSide(j, "h", source);
  if (!t->fl_x && !t->camera_angle_x) {
    throw InputError(source, "camera_angle_x", "", "missing: the file gives no focal length",
                     "add \"camera_angle_x\" (radians) or \"fl_x\" (pixels)");
  }
}

// A camera-to-world matrix: 3 or 4 rows of 4 finite numbers (a 4th row is not read), with an
// orthonormal, right-handed rotation.
Eigen::Matrix<double, 3, 4> ReadCamToWorld(const json& m, const std::string& source, const std::string& field) {
  Eigen::Matrix<double, 3, 4> c2w;
  bool ok = m.is_array() && (m.size() == 3 || m.size() == 4);
  for (size_t r = 0; ok && r < m.size(); ++r) {
    ok = m[r].is_array() && m[r].size() == 4;
    for (int c = 0; ok && c < 4; ++c) {
      ok = m[r][c].is_number() && std::isfinite(m[r][c].get<double>());
      if (ok && r < 3) c2w(static_cast<int>(r), c) = m[r][c].get<double>();
    }
  }
  if (!ok) throw InputError(source, field, Shown(m), "expected a 4x4 (or 3x4) array of finite numbers");
  const Eigen::Matrix3d r_blender = c2w.leftCols<3>();
  if (!(r_blender.transpose() * r_blender).isIdentity(1e-3) || r_blender.determinant() < 0) {
    throw InputError(source, field, Shown(m), "the rotation part is not orthonormal (scaled or mirrored camera)",
                     "write pure rotation + translation camera-to-world matrices");
  }
  return c2w;
}

NerfFrame ReadFrame(const json& f, const fs::path& base, const std::string& source, const std::string& field) {
  if (!f.is_object() || !f.contains("file_path") || !f["file_path"].is_string()) {
    throw InputError(source, field + ".file_path", "", "missing or not a string");
  }
  NerfFrame frame;
  frame.file_path = f["file_path"].get<std::string>();
  fs::path p = base / frame.file_path;
  // NeRF-synthetic writes paths without extension ("./train/r_0"): the images are PNG.
  if (!HasImageExtension(p)) p += ".png";
  frame.image_path = p.lexically_normal();

  if (!f.contains("transform_matrix")) throw InputError(source, field + ".transform_matrix", "", "missing");
  const Eigen::Matrix<double, 3, 4> c2w = ReadCamToWorld(f["transform_matrix"], source, field + ".transform_matrix");
  // Blender camera (x right, y up, looking down -z) -> PERF camera (x right, y down, +z).
  Eigen::Matrix3d r = c2w.leftCols<3>();
  r.col(1) *= -1;
  r.col(2) *= -1;
  // Re-orthonormalise the 1e-3 slack away so that downstream checks hold exactly.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
  frame.world_from_cam.leftCols<3>() = svd.matrixU() * svd.matrixV().transpose();
  frame.world_from_cam.col(3) = c2w.col(3);
  return frame;
}

NerfTransforms ReadParsed(const json& j, const fs::path& json_path) {
  const std::string source = json_path.string();
  if (!j.is_object()) throw InputError(source, "", "", "expected a JSON object at the top level");
  NerfTransforms t;
  ReadIntrinsics(j, source, &t);
  if (!j.contains("frames") || !j["frames"].is_array() || j["frames"].empty()) {
    throw InputError(source, "frames", "", "missing or empty: no images listed");
  }
  const json& frames = j["frames"];
  for (size_t i = 0; i < frames.size(); ++i) {
    t.frames.push_back(ReadFrame(frames[i], json_path.parent_path(), source, StrCat("frames[", i, "]")));
  }
  return t;
}

}  // namespace

void NerfTransforms::Intrinsics(int w, int h, const std::string& source, double* fx, double* fy, double* px,
                                double* py) const {
  if (fl_x) {
    *fx = *fl_x;
    *fy = fl_y ? *fl_y : *fl_x;
  } else if (camera_angle_x) {
    *fx = 0.5 * w / std::tan(0.5 * *camera_angle_x);
    *fy = camera_angle_y ? 0.5 * h / std::tan(0.5 * *camera_angle_y) : *fx;
  } else {
    throw InputError(source, "camera_angle_x", "", "missing: the file gives no focal length",
                     "add \"camera_angle_x\" (radians) or \"fl_x\" (pixels)");
  }
  // instant-ngp's cx/cy are given for the json's w/h; rescale if the image differs.
  const double sx = width ? static_cast<double>(w) / *width : 1.0;
  const double sy = height ? static_cast<double>(h) / *height : 1.0;
  if (fl_x) {
    *fx *= sx;
    *fy *= sy;
  }
  *px = cx ? *cx * sx : 0.5 * w;
  *py = cy ? *cy * sy : 0.5 * h;
  // Extreme but finite values (a field of view of 1e-320, fl_x 1e308) can still overflow here.
  using Field = std::pair<const char*, std::optional<double>>;
  const Field fx_from = fl_x ? Field{"fl_x", fl_x} : Field{"camera_angle_x", camera_angle_x};
  Field fy_from = fx_from;
  if (fl_x && fl_y) fy_from = {"fl_y", fl_y};
  if (!fl_x && camera_angle_y) fy_from = {"camera_angle_y", camera_angle_y};
  const auto check = [&](double v, bool focal, const Field& from) {
    if (std::isfinite(v) && (!focal || v > 0)) return;
    throw InputError(source, from.first, from.second ? StrCat(*from.second) : "",
                     StrCat("gives ", v, " pixels for ", w, "x", h, " images"), "check the camera intrinsics");
  };
  check(*fx, true, fx_from);
  check(*fy, true, fy_from);
  check(*px, false, {"cx", cx});
  check(*py, false, {"cy", cy});
}

NerfTransforms ReadNerfTransforms(std::istream& in, const fs::path& json_path) {
  json j;
  try {
    j = json::parse(in);
  } catch (const json::exception& e) {
    // Syntax errors, and numbers no double holds (1e400), which nlohmann reports as out_of_range.
    throw InputError(json_path.string(), "", "", StrCat("not valid JSON (", e.what(), ")"),
                     "check the file is a NeRF transforms.json; numbers must fit a double");
  }
  return ReadParsed(j, json_path);
}

NerfTransforms ReadNerfTransforms(const fs::path& json_path) {
  if (std::error_code ec; !fs::exists(json_path, ec)) {
    throw IoError(json_path.string(), "file not found", "pass the path of a NeRF transforms.json with --nerf");
  }
  // Never blocks on a FIFO nor reads a device without end: "not a regular file" (InputError).
  std::istringstream in(ReadFileToString(json_path));
  return ReadNerfTransforms(in, json_path);
}

}  // namespace perf
