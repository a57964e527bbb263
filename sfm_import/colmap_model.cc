// COLMAP sparse model I/O in COLMAP's own formats (src/base/reconstruction.cc in 3.8,
// src/colmap/scene/reconstruction_io.cc later), split as COLMAP splits it: the binary files
// (colmap_model_binary.cc), the text files (colmap_model_text.cc), and here the checks every
// model gets and the folders.
#include "sfm_import/colmap_model.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <map>
#include <string_view>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_model_common.h"

namespace fs = std::filesystem;

namespace perf::colmap {

namespace detail {

std::string Printable(std::string_view s) {
  std::string out;
  for (const char c : s.substr(0, 120)) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) {
      out += StrCat("\\x", "0123456789abcdef"[u >> 4], "0123456789abcdef"[u & 15]);
    } else {
      out += c;
    }
  }
  if (s.size() > 120) out += "...";
  return out;
}

std::string NameProblem(std::string_view name) {
  if (name.empty()) return "empty image name";
  if (name.size() > kMaxNameBytes) return StrCat("longer than ", kMaxNameBytes, " bytes");
  for (const char c : name) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) return "contains a control character";
  }
  return {};
}

const CameraModelInfo& ModelForWriting(const Camera& cam) {
  const CameraModelInfo* model = FindCameraModel(cam.model_id);
  PERF_CHECK_MSG(model != nullptr, "camera ", cam.camera_id, " model id ", cam.model_id);
  PERF_CHECK_MSG(static_cast<int>(cam.params.size()) == model->num_params, "camera ", cam.camera_id,
                 " has ", cam.params.size(), " params for ", model->name);
  return *model;
}

void CheckNameForWriting(const Image& image) {
  PERF_CHECK_MSG(NameProblem(image.name).empty(), "image ", image.image_id, " name");
}

}  // namespace detail

using namespace detail;

// ---------------------------------------------------------------------------------------------
// Validation.

namespace {
// A model that reads but does not hang together.
[[noreturn]] void Invalid(const std::string& source, const std::string& field,
                          const std::string& value, const std::string& problem,
                          const std::string& hint) {
  throw InputError(source, field, value, problem, hint);
}
}  // namespace

void ValidateReconstruction(const Reconstruction& rec, const std::string& source) {
  if (rec.images.empty()) {
    Invalid(source, "images", "0", "empty model (no images)",
            StrCat("COLMAP registered no images in this model; check that the reconstruction "
                   "succeeded and ",
                   kFolderHint));
  }

  for (const auto& [id, cam] : rec.cameras) {
    PERF_CHECK(cam.camera_id == id);
    const auto what = [id = id] { return StrCat("camera ", id); };
    const CameraModelInfo* model = FindCameraModel(cam.model_id);
    if (model == nullptr) {
      Invalid(source, what() + " model_id", std::to_string(cam.model_id), "unknown camera model id",
              kModelIdHint);
    }
    if (static_cast<int>(cam.params.size()) != model->num_params) {
      Invalid(source, what() + " params", StrCat(cam.params.size(), " values"),
              "wrong number of parameters",
              StrCat("model ", model->name, " takes ", model->num_params, ": ", model->params));
    }
    if (!AllFinite(cam.params)) {
      Invalid(source, what() + " params", ListValues(cam.params), "not finite (NaN or inf)",
              kReexportHint);
    }
    for (const auto& [field, v] :
         {std::pair{"width", cam.width}, std::pair{"height", cam.height}}) {
      if (v == 0 || v > kMaxImageSide) {
        Invalid(source, StrCat(what(), " ", field), std::to_string(v),
                v == 0 ? "image size is zero" : "implausibly large image size", kReexportHint);
      }
    }
  }

  std::map<std::string_view, uint32_t> ids_by_name;  // one pose per photo
  for (const auto& [id, image] : rec.images) {
    PERF_CHECK(image.image_id == id);
    const auto what = [&im = image] {
      return StrCat("image \"", Printable(im.name), "\" (id ", im.image_id, ")");
    };
    if (const auto [it, fresh] = ids_by_name.emplace(image.name, id); !fresh) {
      Invalid(source, what() + " name", Printable(image.name),
              StrCat("image ", it->second, " has the same name: one photo with two poses"), kReexportHint);
    }
    if (rec.cameras.count(image.camera_id) == 0) {
      Invalid(source, what() + " camera_id", std::to_string(image.camera_id),
              "no camera with this id in the cameras file", kMismatchHint);
    }
    if (!AllFinite(image.qvec) || !AllFinite(image.tvec)) {
      Invalid(source, what() + " pose",
              StrCat("qvec ", ListValues(image.qvec), ", tvec ", ListValues(image.tvec)),
              "not finite (NaN or inf)", kReexportHint);
    }
    double norm2 = 0;
    for (const double q : image.qvec) norm2 += q * q;
    const double norm = std::sqrt(norm2);
    if (std::abs(norm - 1.0) > 1e-3) {
      Invalid(source, what() + " qvec", StrCat(ListValues(image.qvec), " (norm ", norm, ")"),
              "not a unit quaternion (the norm must be within 1e-3 of 1)",
              StrCat("COLMAP always writes unit quaternions; ", kReexportHint));
    }
  }

  for (const auto& [id, p] : rec.points3D) {
    PERF_CHECK(p.point3D_id == id);
    // Messages are built only on failure: bonsai alone has 30k points.
    const auto what = [id = id] { return StrCat("point3D ", id); };
    if (!AllFinite(p.xyz)) {
      Invalid(source, what() + " xyz", ListValues(p.xyz), "not finite (NaN or inf)", kReexportHint);
    }
    for (size_t k = 0; k < p.track.size(); ++k) {
      const TrackElement& t = p.track[k];
      const auto image = rec.images.find(t.image_id);
      if (image == rec.images.end()) {
        Invalid(source, StrCat(what(), " track[", k, "] image_id"), std::to_string(t.image_id),
                "no image with this id in the images file", kMismatchHint);
      }
      if (t.point2D_idx >= image->second.points2D.size()) {
        Invalid(source, StrCat(what(), " track[", k, "] point2D_idx"),
                std::to_string(t.point2D_idx),
                StrCat("out of range: image ", t.image_id, " has ", image->second.points2D.size(),
                       " points2D"),
                kMismatchHint);
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Folders.

namespace {

constexpr const char* kBinaryFiles[] = {"cameras.bin", "images.bin", "points3D.bin"};
constexpr const char* kTextFiles[] = {"cameras.txt", "images.txt", "points3D.txt"};

// The files of `files` that are not in `dir`, comma separated (one that is there but is not a
// regular file, a FIFO say, is not missing: ReadFile names it).
std::string Missing(const fs::path& dir, const char* const (&files)[3]) {
  std::string missing;
  for (const char* f : files) {
    std::error_code ec;
    if (!fs::exists(dir / f, ec)) missing += StrCat(missing.empty() ? "" : ", ", f);
  }
  return missing;
}

void ReadFile(const fs::path& path,
              void (*read)(std::istream&, const std::string&, Reconstruction*),
              Reconstruction* rec) {
  CheckRegularFile(path);  // a FIFO would block the open below for ever
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), StrCat("cannot open for reading: ", std::strerror(errno)));
  read(in, path.string(), rec);
}

void WriteFile(const fs::path& path, void (*write)(std::ostream&, const Reconstruction&),
               const Reconstruction& rec) {
  WriteStreamAtomically(path, [&](std::ostream& out) { write(out, rec); });
}

}  // namespace

ModelFormat DetectModelFormat(const fs::path& dir) {
  std::error_code ec;
  const fs::file_status status = fs::status(dir, ec);
  if (!fs::exists(status))
    throw InputError(dir.string(), "", "", "folder does not exist", kFolderHint);
  if (!fs::is_directory(status))
    throw InputError(dir.string(), "", "", "not a folder", kFolderHint);
  const std::string missing_bin = Missing(dir, kBinaryFiles);
  if (missing_bin.empty()) return ModelFormat::kBinary;
  const std::string missing_txt = Missing(dir, kTextFiles);
  if (missing_txt.empty()) return ModelFormat::kText;

  // A common slip is pointing at the project or sparse/ folder instead of the model inside.
  std::string hint = kFolderHint;
  for (const char* sub : {"0", "sparse/0"}) {
    if (Missing(dir / sub, kBinaryFiles).empty() || Missing(dir / sub, kTextFiles).empty()) {
      hint += StrCat("; ", (dir / sub).string(), " holds a model");
      break;
    }
  }
  throw InputError(dir.string(), "", "",
                   StrCat("not a COLMAP model folder: missing ", missing_bin,
                          " (binary model) and ", missing_txt, " (text model)"),
                   hint);
}

Reconstruction ReadReconstruction(const fs::path& dir) {
  Reconstruction rec;
  if (DetectModelFormat(dir) == ModelFormat::kBinary) {
    ReadFile(dir / "cameras.bin", ReadCamerasBinary, &rec);
    ReadFile(dir / "images.bin", ReadImagesBinary, &rec);
    ReadFile(dir / "points3D.bin", ReadPoints3DBinary, &rec);
  } else {
    ReadFile(dir / "cameras.txt", ReadCamerasText, &rec);
    ReadFile(dir / "images.txt", ReadImagesText, &rec);
    ReadFile(dir / "points3D.txt", ReadPoints3DText, &rec);
  }
  ValidateReconstruction(rec, dir.string());
  return rec;
}

void WriteReconstruction(const fs::path& dir, const Reconstruction& rec, ModelFormat format) {
  EnsureWritableDirectory(dir);
  if (format == ModelFormat::kBinary) {
    WriteFile(dir / "cameras.bin", WriteCamerasBinary, rec);
    WriteFile(dir / "images.bin", WriteImagesBinary, rec);
    WriteFile(dir / "points3D.bin", WritePoints3DBinary, rec);
  } else {
    WriteFile(dir / "cameras.txt", WriteCamerasText, rec);
    WriteFile(dir / "images.txt", WriteImagesText, rec);
    WriteFile(dir / "points3D.txt", WritePoints3DText, rec);
  }
}

}  // namespace perf::colmap
