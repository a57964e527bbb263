// COLMAP sparse models (cameras, images, points3D) in COLMAP's binary and text formats.
//
// Every reader validates as it goes and throws perf::InputError naming the file, the record
// and field, and the bad value: truncated or garbled files, counts that disagree with the file
// size, unknown camera models, references to missing cameras/images, NaN or non-unit
// quaternions. Readers never allocate more than the file can hold, so no input can make them
// crash or hang (there is a libFuzzer target in fuzz/).
//
// Every reader/writer has a stream overload (with a name used in messages) and a path
// overload that only opens, checks and delegates. Text writers use full precision.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <map>
#include <string>
#include <vector>

namespace perf::colmap {

inline constexpr uint64_t kInvalidPoint3DId = static_cast<uint64_t>(-1);

struct Camera {
  uint32_t camera_id = 0;
  int model_id = 0;  // a CameraModelId value (kept as int: files may hold unknown ids)
  uint64_t width = 0, height = 0;
  std::vector<double> params;  // in the model's order (camera_models.h)
};

struct Point2D {
  double x = 0, y = 0;  // pixels, COLMAP convention (upper-left pixel centre at 0.5, 0.5)
  uint64_t point3D_id = kInvalidPoint3DId;
};

struct Image {
  uint32_t image_id = 0;
  std::array<double, 4> qvec = {1, 0, 0, 0};  // cam_from_world rotation, (w, x, y, z)
  std::array<double, 3> tvec = {0, 0, 0};     // cam_from_world translation
  uint32_t camera_id = 0;
  std::string name;  // path relative to the image folder, '/' separated
  std::vector<Point2D> points2D;
};

struct TrackElement {
  uint32_t image_id = 0;
  uint32_t point2D_idx = 0;
};

struct Point3D {
  uint64_t point3D_id = 0;
  std::array<double, 3> xyz = {0, 0, 0};
  std::array<uint8_t, 3> rgb = {0, 0, 0};
  double error = -1;  // mean reprojection error in pixels, -1 if unknown
  std::vector<TrackElement> track;
};

struct Reconstruction {
  std::map<uint32_t, Camera> cameras;
  std::map<uint32_t, Image> images;
  std::map<uint64_t, Point3D> points3D;
};

enum class ModelFormat { kBinary, kText };

// Which format the folder holds: binary if cameras.bin, images.bin and points3D.bin are there,
// else text if the three .txt files are, else InputError listing what is missing.
ModelFormat DetectModelFormat(const std::filesystem::path& dir);

// Reads the model in `dir` (format detected) and validates it (ValidateReconstruction).
Reconstruction ReadReconstruction(const std::filesystem::path& dir);

// Writes cameras/images/points3D in the given format into `dir` (atomically per file).
void WriteReconstruction(const std::filesystem::path& dir, const Reconstruction& rec,
                         ModelFormat format);

// Cross-checks: every image's camera exists, every track element names an existing image and
// an in-range point2D, every quaternion is finite and unit (|q| within 1e-3 of 1), parameter
// counts match the model, at least one image. `source` names the folder in messages.
void ValidateReconstruction(const Reconstruction& rec, const std::string& source);

// Per-file readers and writers. `name` is used in error messages (the file's path).
void ReadCamerasBinary(std::istream& in, const std::string& name, Reconstruction* rec);
void ReadImagesBinary(std::istream& in, const std::string& name, Reconstruction* rec);
void ReadPoints3DBinary(std::istream& in, const std::string& name, Reconstruction* rec);
void ReadCamerasText(std::istream& in, const std::string& name, Reconstruction* rec);
void ReadImagesText(std::istream& in, const std::string& name, Reconstruction* rec);
void ReadPoints3DText(std::istream& in, const std::string& name, Reconstruction* rec);

void WriteCamerasBinary(std::ostream& out, const Reconstruction& rec);
void WriteImagesBinary(std::ostream& out, const Reconstruction& rec);
void WritePoints3DBinary(std::ostream& out, const Reconstruction& rec);
void WriteCamerasText(std::ostream& out, const Reconstruction& rec);
void WriteImagesText(std::ostream& out, const Reconstruction& rec);
void WritePoints3DText(std::ostream& out, const Reconstruction& rec);

}  // namespace perf::colmap
