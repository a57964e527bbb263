#include "workspace/scene.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/world_range.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace perf {
namespace {

json Vec3ToJson(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

template <int R, int C>
json MatToJson(const Eigen::Matrix<double, R, C>& m) {
  json rows = json::array();
  for (int r = 0; r < R; ++r) {
    json row = json::array();
    for (int c = 0; c < C; ++c) row.push_back(m(r, c));
    rows.push_back(row);
  }
  return rows;
}

// Reading with context: every failure names the file and the JSON path of the field.
class Reader {
 public:
  explicit Reader(std::string name) : name_(std::move(name)) {}

  [[noreturn]] void Fail(const std::string& field, const json& value, const std::string& problem) const {
    std::string shown = value.is_null() ? "" : value.dump();
    if (shown.size() > 80) shown = shown.substr(0, 77) + "...";
    throw InputError(name_, field, shown, problem,
                     "re-run `perf import` to regenerate scene.json, or fix the field by hand");
  }

  const json& Get(const json& obj, const std::string& key, const std::string& path) const {
    if (!obj.is_object() || !obj.contains(key)) Fail(path + "." + key, nullptr, "missing field");
    return obj.at(key);
  }

  double Number(const json& v, const std::string& path) const {
    if (!v.is_number()) Fail(path, v, "expected a number");
    const double d = v.get<double>();
    if (!std::isfinite(d)) Fail(path, v, "not a finite number");
    return d;
  }

  int Int(const json& v, const std::string& path) const {
    if (!v.is_number_integer()) Fail(path, v, "expected an integer");
    return v.get<int>();
  }

  std::string String(const json& v, const std::string& path) const {
    if (!v.is_string()) Fail(path, v, "expected a string");
    return v.get<std::string>();
  }

  Eigen::Vector3d Vec3(const json& v, const std::string& path) const {
    if (!v.is_array() || v.size() != 3) Fail(path, v, "expected an array of 3 numbers");
    return {Number(v[0], path + "[0]"), Number(v[1], path + "[1]"), Number(v[2], path + "[2]")};
  }

  template <int R, int C>
  Eigen::Matrix<double, R, C> Mat(const json& v, const std::string& path) const {
    if (!v.is_array() || v.size() != R) Fail(path, v, StrCat("expected ", R, " rows of ", C, " numbers"));
    Eigen::Matrix<double, R, C> m;
    for (int r = 0; r < R; ++r) {
      if (!v[r].is_array() || v[r].size() != C) Fail(path, v, StrCat("expected ", R, " rows of ", C, " numbers"));
      for (int c = 0; c < C; ++c) m(r, c) = Number(v[r][c], StrCat(path, "[", r, "][", c, "]"));
    }
    return m;
  }

  const std::string& name() const { return name_; }

 private:
  std::string name_;
};

}  // namespace

const SceneCamera& Scene::camera(int id) const {
  for (const auto& c : cameras) {
    if (c.id == id) return c;
  }
  PERF_CHECK_MSG(false, "no camera with id ", id);
  throw;  // unreachable
}

const char* SplitName(Split split) {
  switch (split) {
    case Split::kTrain: return "train";
    case Split::kTest: return "test";
    case Split::kExcluded: return "excluded";
  }
  return "?";
}

bool EveryImageHasAlpha(const Scene& scene) {
  return !scene.images.empty() && std::all_of(scene.images.begin(), scene.images.end(),
                                              [](const SceneImage& im) { return !im.alpha_path.empty(); });
}

bool AnyExcluded(const Scene& scene) {
  return std::any_of(scene.images.begin(), scene.images.end(), [](const SceneImage& im) { return im.split == Split::kExcluded; });
}

std::string SceneToJson(const Scene& scene) {
  json j;
  j["format"] = "perf-scene";
  j["version"] = scene.version;
  j["conventions"] = {
      {"camera_frame", "x right, y down, z forward (COLMAP/OpenCV)"},
      {"pixel_centre", "upper-left pixel centre at (0.5, 0.5)"},
      {"pose", "world_from_cam: 3x4 camera-to-world [R | t]"},
  };
  j["source"] = {{"type", scene.source.type},
                 {"path", scene.source.path},
                 {"images", scene.source.images},
                 {"format", scene.source.format},
                 {"downscale", scene.source.downscale},
                 {"max_size", scene.source.max_size}};
  j["color"] = {{"encoding", scene.color_encoding}, {"background", Vec3ToJson(scene.background)}};
  j["box"] = {{"center", Vec3ToJson(scene.box.center)},
              {"size", Vec3ToJson(scene.box.size)},
              {"rotation", MatToJson<3, 3>(scene.box.rotation)},
              {"method", scene.box.method}};
  j["shells"] = {{"center", Vec3ToJson(scene.shells.center)}, {"radii", scene.shells.radii}};
  json cams = json::array();
  for (const auto& c : scene.cameras) {
    cams.push_back({{"id", c.id},
                    {"model", "PINHOLE"},
                    {"width", c.width},
                    {"height", c.height},
                    {"fx", c.fx},
                    {"fy", c.fy},
                    {"cx", c.cx},
                    {"cy", c.cy},
                    {"source", {{"model", c.source.model},
                                {"params", c.source.params},
                                {"width", c.source.width},
                                {"height", c.source.height}}}});
  }
  j["cameras"] = cams;
  json imgs = json::array();
  for (const auto& im : scene.images) {
    json e = {{"name", im.name},
              {"path", im.path},
              {"source_path", im.source_path},
              {"camera_id", im.camera_id},
              {"split", SplitName(im.split)},
              {"world_from_cam", MatToJson<3, 4>(im.world_from_cam)}};
    if (im.split == Split::kExcluded) e["excluded_because"] = im.excluded_because;
    if (!im.pose_doubt.empty()) e["pose_doubt"] = im.pose_doubt;
    if (im.turn_group >= 0) e["turn_group"] = im.turn_group;
    if (!im.alpha_path.empty()) e["alpha_path"] = im.alpha_path;
    if (im.refined_world_from_cam) e["refined_world_from_cam"] = MatToJson<3, 4>(*im.refined_world_from_cam);
    if (im.refined_focal_scale) e["refined_focal_scale"] = *im.refined_focal_scale;
    imgs.push_back(e);
  }
  j["images"] = imgs;
  // nlohmann::json prints doubles with the shortest representation that round-trips.
  return j.dump(2) + "\n";
}

Scene SceneFromJson(const std::string& text, const std::string& name) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, and out_of_range for numbers like 1e400
    throw InputError(name, "", "", StrCat("not valid JSON (", e.what(), ")"),
                     "the file is corrupt; re-run `perf import`");
  }
  Reader r(name);
  if (!j.is_object() || j.value("format", "") != "perf-scene") {
    r.Fail("format", j.is_object() && j.contains("format") ? j["format"] : json(nullptr),
           "not a PERF scene.json (expected \"format\": \"perf-scene\")");
  }
  Scene s;
  s.version = r.Int(r.Get(j, "version", ""), "version");
  if (s.version != kSceneVersion) {
    r.Fail("version", j["version"], StrCat("unsupported scene.json version (this perf reads version ", kSceneVersion, ")"));
  }
  const json& src = r.Get(j, "source", "");
  s.source.type = r.String(r.Get(src, "type", "source"), "source.type");
  s.source.path = r.String(r.Get(src, "path", "source"), "source.path");
  s.source.images = r.String(r.Get(src, "images", "source"), "source.images");
  s.source.format = r.String(r.Get(src, "format", "source"), "source.format");
  s.source.downscale = r.Int(r.Get(src, "downscale", "source"), "source.downscale");
  // Recorded since 2026-12-06; -1 in older scenes.
  s.source.max_size = src.contains("max_size") ? r.Int(src["max_size"], "source.max_size") : -1;
  const json& color = r.Get(j, "color", "");
  s.color_encoding = r.String(r.Get(color, "encoding", "color"), "color.encoding");
  s.background = r.Vec3(r.Get(color, "background", "color"), "color.background");

  const json& box = r.Get(j, "box", "");
  s.box.center = r.Vec3(r.Get(box, "center", "box"), "box.center");
  s.box.size = r.Vec3(r.Get(box, "size", "box"), "box.size");
  s.box.rotation = r.Mat<3, 3>(r.Get(box, "rotation", "box"), "box.rotation");
  s.box.method = box.value("method", "");
  if (!(s.box.size.array() >= kMinBoxSide).all() || !(s.box.size.array() <= kMaxWorldSpan).all()) {
    r.Fail("box.size", box["size"], StrCat("box sides must be ", kMinBoxSide, " to ", kMaxWorldSpan, " world units"));
  }
  if (!(s.box.center.array().abs() <= kMaxWorldSpan).all()) {
    r.Fail("box.center", box["center"], StrCat("must be within ", kMaxWorldSpan, " world units of the origin"));
  }
  if (!(s.box.rotation.transpose() * s.box.rotation).isIdentity(1e-6)) {
    r.Fail("box.rotation", box["rotation"], "not a rotation matrix");
  }

  const json& shells = r.Get(j, "shells", "");
  s.shells.center = r.Vec3(r.Get(shells, "center", "shells"), "shells.center");
  if (!(s.shells.center.array().abs() <= kMaxWorldSpan).all()) {
    r.Fail("shells.center", shells["center"], StrCat("must be within ", kMaxWorldSpan, " world units of the origin"));
  }
  const json& radii = r.Get(shells, "radii", "shells");
  if (!radii.is_array() || radii.empty() || radii.size() > kMaxSceneShells) {
    r.Fail("shells.radii", radii, StrCat("expected an array of 1 to ", kMaxSceneShells, " radii"));
  }
  for (size_t i = 0; i < radii.size(); ++i) {
    const double v = r.Number(radii[i], StrCat("shells.radii[", i, "]"));
    if (v <= 0 || (!s.shells.radii.empty() && v <= s.shells.radii.back())) {
      r.Fail(StrCat("shells.radii[", i, "]"), radii[i], "radii must be positive and strictly increasing");
    }
    if (v > kMaxWorldSpan) r.Fail(StrCat("shells.radii[", i, "]"), radii[i], StrCat("must be at most ", kMaxWorldSpan));
    s.shells.radii.push_back(v);
  }

  const json& cams = r.Get(j, "cameras", "");
  if (!cams.is_array() || cams.empty()) r.Fail("cameras", cams, "expected a non-empty array");
  for (size_t i = 0; i < cams.size(); ++i) {
    const std::string p = StrCat("cameras[", i, "]");
    const json& c = cams[i];
    SceneCamera cam;
    cam.id = r.Int(r.Get(c, "id", p), p + ".id");
    cam.width = r.Int(r.Get(c, "width", p), p + ".width");
    cam.height = r.Int(r.Get(c, "height", p), p + ".height");
    if (cam.width <= 0 || cam.height <= 0) r.Fail(p + ".width/height", c["width"], "image size must be positive");
    cam.fx = r.Number(r.Get(c, "fx", p), p + ".fx");
    cam.fy = r.Number(r.Get(c, "fy", p), p + ".fy");
    cam.cx = r.Number(r.Get(c, "cx", p), p + ".cx");
    cam.cy = r.Number(r.Get(c, "cy", p), p + ".cy");
    if (cam.fx <= 0 || cam.fy <= 0) r.Fail(p + ".fx", c["fx"], "focal lengths must be positive");
    const json& sc = r.Get(c, "source", p);
    cam.source.model = r.String(r.Get(sc, "model", p + ".source"), p + ".source.model");
    cam.source.width = r.Int(r.Get(sc, "width", p + ".source"), p + ".source.width");
    cam.source.height = r.Int(r.Get(sc, "height", p + ".source"), p + ".source.height");
    const json& params = r.Get(sc, "params", p + ".source");
    if (!params.is_array()) r.Fail(p + ".source.params", params, "expected an array");
    for (size_t k = 0; k < params.size(); ++k) {
      cam.source.params.push_back(r.Number(params[k], StrCat(p, ".source.params[", k, "]")));
    }
    for (const auto& other : s.cameras) {
      if (other.id == cam.id) r.Fail(p + ".id", c["id"], "duplicate camera id");
    }
    s.cameras.push_back(std::move(cam));
  }

  const json& imgs = r.Get(j, "images", "");
  if (!imgs.is_array() || imgs.empty()) r.Fail("images", imgs, "expected a non-empty array");
  for (size_t i = 0; i < imgs.size(); ++i) {
    const std::string p = StrCat("images[", i, "]");
    const json& e = imgs[i];
    SceneImage im;
    im.name = r.String(r.Get(e, "name", p), p + ".name");
    im.path = r.String(r.Get(e, "path", p), p + ".path");
    im.source_path = e.value("source_path", "");
    im.alpha_path = e.value("alpha_path", "");
    for (const auto& [field, value] : {std::pair{".path", &im.path}, std::pair{".alpha_path", &im.alpha_path}}) {
      if (!value->empty() && !IsInsideWorkspace(*value)) {
        r.Fail(p + field, json(*value), "must be a relative path inside the workspace (no \"..\", no leading /)");
      }
    }
    im.camera_id = r.Int(r.Get(e, "camera_id", p), p + ".camera_id");
    bool found = false;
    for (const auto& c : s.cameras) found = found || c.id == im.camera_id;
    if (!found) r.Fail(p + ".camera_id", e["camera_id"], "no camera with this id in \"cameras\"");
    const std::string split = r.String(r.Get(e, "split", p), p + ".split");
    if (split != "train" && split != "test" && split != "excluded") {
      r.Fail(p + ".split", e["split"], "expected \"train\", \"test\" or \"excluded\"");
    }
    im.split = split == "train" ? Split::kTrain : split == "test" ? Split::kTest : Split::kExcluded;
    if (im.split == Split::kExcluded && e.contains("excluded_because")) {
      im.excluded_because = r.String(e["excluded_because"], p + ".excluded_because");
    }
    if (e.contains("pose_doubt")) im.pose_doubt = r.String(e["pose_doubt"], p + ".pose_doubt");
    if (e.contains("turn_group")) {
      im.turn_group = r.Int(e["turn_group"], p + ".turn_group");
      if (im.turn_group < 0) r.Fail(p + ".turn_group", e["turn_group"], "expected a group number, 0 or more");
    }
    for (const char* field : {"world_from_cam", "refined_world_from_cam"}) {
      if (!e.contains(field) && std::string(field) != "world_from_cam") continue;
      const Eigen::Matrix<double, 3, 4> pose = r.Mat<3, 4>(r.Get(e, field, p), p + "." + field);
      const Eigen::Matrix3d R = pose.leftCols<3>();
      if (!(R.transpose() * R).isIdentity(1e-6) || R.determinant() < 0) {
        r.Fail(p + "." + field, e[field], "the 3x3 part is not a rotation");
      }
      if (std::string(field) == "world_from_cam") {
        im.world_from_cam = pose;
      } else {
        im.refined_world_from_cam = pose;
      }
    }
    if (e.contains("refined_focal_scale")) {
      const double f = r.Number(e["refined_focal_scale"], p + ".refined_focal_scale");
      if (!(f > 0.5 && f < 2)) {
        r.Fail(p + ".refined_focal_scale", e["refined_focal_scale"], "must be a scale of the focal length in (0.5, 2)");
      }
      im.refined_focal_scale = f;
    }
    s.images.push_back(std::move(im));
  }
  return s;
}

void WriteScene(const fs::path& path, const Scene& scene) {
  WriteFileAtomically(path, SceneToJson(scene), Durability::kDurable);
}

std::string WorkspaceSafeName(std::string_view name) {
  std::string out;
  std::string part;
  const auto flush = [&] {
    if (part.empty() || part == ".") {
      part.clear();
      return;
    }
    if (part == "..") part = "_up_";
    if (!out.empty()) out += '/';
    out += part;
    part.clear();
  };
  for (const char ch : name) {
    const auto c = static_cast<unsigned char>(ch);
    if (c == '/') {
      flush();
    } else {
      part += (c < 0x20 || c == 0x7f || c == '\\') ? '_' : ch;
    }
  }
  flush();
  return out.empty() ? std::string("_") : out;
}

bool IsInsideWorkspace(std::string_view path) {
  return !path.empty() && WorkspaceSafeName(path) == path;
}

Scene ReadScene(const fs::path& path) {
  if (!fs::exists(path)) {
    throw IoError(path.string(), "no scene.json here", "run `perf import` on this workspace first");
  }
  return SceneFromJson(ReadFileToString(path), path.string());
}

}  // namespace perf
