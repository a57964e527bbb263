#include "sfm_import/nerf_reader.h"

#include <Eigen/Dense>
#include <cmath>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "sfm_import/image_io.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace perf {
namespace {

std::optional<double> OptNumber(const json& j, const char* key, const std::string& source) {
  if (!j.contains(key)) return std::nullopt;
  const json& v = j[key];
  if (!v.is_number() || !std::isfinite(v.get<double>())) {
    throw InputError(source, key, v.dump(), "expected a finite number");
  }
  return v.get<double>();
}

}  // namespace

void NerfTransforms::Intrinsics(int w, int h, const std::string& source, double* fx, double* fy,
                                double* px, double* py) const {
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
}

NerfTransforms ReadNerfTransforms(const fs::path& json_path) {
  const std::string source = json_path.string();
  if (!fs::is_regular_file(json_path)) {
    throw IoError(source, "file not found", "pass the path of a NeRF transforms.json with --nerf");
  }
  json j;
  try {
    j = json::parse(ReadFileToString(json_path));
  } catch (const json::parse_error& e) {
    throw InputError(source, "", "", StrCat("not valid JSON (", e.what(), ")"));
  }
  if (!j.is_object()) throw InputError(source, "", "", "expected a JSON object at the top level");

  NerfTransforms t;
  t.camera_angle_x = OptNumber(j, "camera_angle_x", source);
  t.camera_angle_y = OptNumber(j, "camera_angle_y", source);
  t.fl_x = OptNumber(j, "fl_x", source);
  t.fl_y = OptNumber(j, "fl_y", source);
  t.cx = OptNumber(j, "cx", source);
  t.cy = OptNumber(j, "cy", source);
  if (auto w = OptNumber(j, "w", source)) t.width = static_cast<int>(*w);
  if (auto h = OptNumber(j, "h", source)) t.height = static_cast<int>(*h);
  if (t.camera_angle_x && !(*t.camera_angle_x > 0 && *t.camera_angle_x < M_PI)) {
    throw InputError(source, "camera_angle_x", std::to_string(*t.camera_angle_x),
                     "must be a field of view in radians, between 0 and pi");
  }
  if (!t.fl_x && !t.camera_angle_x) {
    throw InputError(source, "camera_angle_x", "", "missing: the file gives no focal length",
                     "add \"camera_angle_x\" (radians) or \"fl_x\" (pixels)");
  }

  if (!j.contains("frames") || !j["frames"].is_array() || j["frames"].empty()) {
    throw InputError(source, "frames", "", "missing or empty: no images listed");
  }
  const fs::path base = json_path.parent_path();
  const json& frames = j["frames"];
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string field = StrCat("frames[", i, "]");
    const json& f = frames[i];
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
    const json& m = f["transform_matrix"];
    Eigen::Matrix4d c2w;
    bool ok = m.is_array() && m.size() >= 3;
    for (int r = 0; ok && r < static_cast<int>(m.size()) && r < 4; ++r) {
      ok = m[r].is_array() && m[r].size() == 4;
      for (int c = 0; ok && c < 4; ++c) {
        ok = m[r][c].is_number() && std::isfinite(m[r][c].get<double>());
        if (ok) c2w(r, c) = m[r][c].get<double>();
      }
    }
    if (!ok) {
      throw InputError(source, field + ".transform_matrix", m.dump().substr(0, 80),
                       "expected a 4x4 array of finite numbers");
    }
    const Eigen::Matrix3d r_blender = c2w.topLeftCorner<3, 3>();
    if (!(r_blender.transpose() * r_blender).isIdentity(1e-3) || r_blender.determinant() < 0) {
      throw InputError(source, field + ".transform_matrix", m.dump().substr(0, 80),
                       "the rotation part is not orthonormal (scaled or mirrored camera)",
                       "write pure rotation + translation camera-to-world matrices");
    }
    // Blender camera (x right, y up, looking down -z) -> PERF camera (x right, y down, +z).
    Eigen::Matrix3d r = r_blender;
    r.col(1) *= -1;
    r.col(2) *= -1;
    // Re-orthonormalise the 1e-3 slack away so that downstream checks hold exactly.
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
    frame.world_from_cam.leftCols<3>() = svd.matrixU() * svd.matrixV().transpose();
    frame.world_from_cam.col(3) = c2w.block<3, 1>(0, 3);
    t.frames.push_back(std::move(frame));
  }
  return t;
}

}  // namespace perf
