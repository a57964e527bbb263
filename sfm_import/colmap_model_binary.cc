// COLMAP's binary model files: little-endian, each a uint64 record count followed by the records
// (layouts in colmap_model.h). Readers slurp the file and read from memory, so every count is
// checked against the bytes actually left before anything is allocated for it: a flipped bit in
// a count gives a clear error instead of a multi-gigabyte allocation or a long loop.
#include <bit>
#include <cstring>
#include <istream>
#include <optional>
#include <ostream>
#include <string_view>
#include <type_traits>

#include "common/errors.h"
#include "sfm_import/colmap_model.h"
#include "sfm_import/colmap_model_common.h"

namespace perf::colmap {

using namespace detail;

namespace {

// ---------------------------------------------------------------------------------------------
// Binary reading and writing.

template <typename T>
using UIntOfSize = std::conditional_t<sizeof(T) == 1, uint8_t,
                                      std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>>;

// Little-endian, whatever the host byte order.
template <typename T>
T DecodeLE(const char* p) {
  using U = UIntOfSize<T>;
  U u = 0;
  for (size_t i = 0; i < sizeof(T); ++i) u |= static_cast<U>(U{uint8_t(p[i])} << (8 * i));
  return std::bit_cast<T>(u);
}

// Writes each value little-endian with its own type's size: PutLE(out, uint32_t{id}, x, y).
template <typename... T>
void PutLE(std::ostream& out, T... values) {
  const auto put = [&out](auto value) {
    const auto u = std::bit_cast<UIntOfSize<decltype(value)>>(value);
    char bytes[sizeof(value)];
    for (size_t i = 0; i < sizeof(value); ++i) bytes[i] = static_cast<char>((u >> (8 * i)) & 0xff);
    out.write(bytes, sizeof(value));
  };
  (put(values), ...);
}

std::string ReadAll(std::istream& in, const std::string& name) {
  std::string data;
  char buf[1 << 16];
  while (in.read(buf, sizeof buf) || in.gcount() > 0) {
    data.append(buf, static_cast<size_t>(in.gcount()));
  }
  if (in.bad()) throw IoError(name, "read failed");
  return data;
}

// A binary file held in memory and read front to back. It knows the record being read, so
// every error names the file, the record ("image #3 (id 7)", counted from 1) and the field.
class ByteReader {
 public:
  ByteReader(std::istream& in, const std::string& name, const char* kind)
      : name_(name), kind_(kind), data_(ReadAll(in, name)) {}

  void BeginRecord(const char* what, uint64_t ordinal) {
    what_ = what;
    ordinal_ = ordinal;
    id_.reset();
  }
  void SetRecordId(uint64_t id) { id_ = id; }

  std::string Field(std::string_view field) const {
    if (what_ == nullptr) return std::string(field);
    return StrCat(what_, " #", ordinal_, id_ ? StrCat(" (id ", *id_, ")") : "", " ", field);
  }

  [[noreturn]] void Fail(std::string_view field, const std::string& value,
                         const std::string& problem, const std::string& hint) const {
    throw InputError(name_, Field(field), value, problem, hint);
  }

  template <typename T>
  T Read(std::string_view field) {
    if (data_.size() - pos_ < sizeof(T)) {
      Fail(field, "", "file ends early (truncated?)",
           StrCat("the file is incomplete or not a COLMAP ", kind_, "; ", kReexportHint));
    }
    const T v = DecodeLE<T>(data_.data() + pos_);
    pos_ += sizeof(T);
    return v;
  }

  template <typename Container>
  void ReadDoubles(Container* values, std::string_view field) {
    for (double& v : *values) v = Read<double>(field);
  }

  // A uint64 element count, checked against what the rest of the file can hold.
  uint64_t ReadCount(std::string_view field, uint64_t min_bytes_each, const char* element) {
    const auto count = Read<uint64_t>(field);
    const uint64_t left = data_.size() - pos_;
    if (count > left / min_bytes_each) {
      Fail(field, std::to_string(count), "count disagrees with file size",
           StrCat(left, " bytes remain but each ", element, " takes at least ", min_bytes_each,
                  "; the file is truncated, corrupt or not a COLMAP ", kind_));
    }
    return count;
  }

  // A NUL-terminated image name, at most kMaxNameBytes long.
  std::string ReadName(std::string_view field) {
    const size_t left = data_.size() - pos_;
    const size_t scan = std::min(left, kMaxNameBytes + 1);
    const char* begin = data_.data() + pos_;
    const auto* nul = static_cast<const char*>(std::memchr(begin, '\0', scan));
    if (nul == nullptr && scan == left) {
      Fail(field, "", "no terminating NUL before the end of the file (truncated?)",
           StrCat("the file is incomplete or not a COLMAP ", kind_));
    }
    if (nul == nullptr) {
      Fail(field, Printable(std::string_view(begin, 40)),
           StrCat("longer than ", kMaxNameBytes, " bytes (no terminating NUL)"),
           StrCat("the file is corrupt or not a COLMAP ", kind_));
    }
    std::string name(begin, nul);
    pos_ += name.size() + 1;
    if (const std::string problem = NameProblem(name); !problem.empty()) {
      Fail(field, Printable(name), problem, "image names must be relative file paths");
    }
    return name;
  }

  // The count at the start must cover the whole file: anything after is corruption.
  void ExpectEnd() {
    what_ = nullptr;
    if (pos_ != data_.size()) {
      Fail("", "", StrCat(data_.size() - pos_, " unexpected bytes after the last record"),
           StrCat("the file is corrupt or not a COLMAP ", kind_));
    }
  }

 private:
  std::string name_;
  const char* kind_;
  std::string data_;
  size_t pos_ = 0;
  const char* what_ = nullptr;
  uint64_t ordinal_ = 0;
  std::optional<uint64_t> id_;
};

}  // namespace

// ---------------------------------------------------------------------------------------------
// Binary readers and writers. Each reader builds its map aside and replaces the one in `rec`
// only when the whole file has been read.

void ReadCamerasBinary(std::istream& in, const std::string& name, Reconstruction* rec) {
  ByteReader r(in, name, "cameras.bin");
  std::map<uint32_t, Camera> cameras;
  const uint64_t n = r.ReadCount("num_cameras", kMinCameraBytes, "camera");
  for (uint64_t i = 0; i < n; ++i) {
    r.BeginRecord("camera", i + 1);
    Camera cam;
    cam.camera_id = r.Read<uint32_t>("camera_id");
    r.SetRecordId(cam.camera_id);
    if (cameras.count(cam.camera_id) != 0) {
      r.Fail("camera_id", std::to_string(cam.camera_id), "duplicate camera id", kReexportHint);
    }
    cam.model_id = r.Read<int32_t>("model_id");
    const CameraModelInfo* model = FindCameraModel(cam.model_id);
    if (model == nullptr) {
      r.Fail("model_id", std::to_string(cam.model_id), "unknown camera model id", kModelIdHint);
    }
    cam.width = r.Read<uint64_t>("width");
    cam.height = r.Read<uint64_t>("height");
    cam.params.resize(static_cast<size_t>(model->num_params));
    r.ReadDoubles(&cam.params, "params");
    cameras.emplace(cam.camera_id, std::move(cam));
  }
  r.ExpectEnd();
  rec->cameras = std::move(cameras);
}

void ReadImagesBinary(std::istream& in, const std::string& name, Reconstruction* rec) {
  ByteReader r(in, name, "images.bin");
  std::map<uint32_t, Image> images;
  const uint64_t n = r.ReadCount("num_images", kMinImageBytes, "image");
  for (uint64_t i = 0; i < n; ++i) {
    r.BeginRecord("image", i + 1);
    Image image;
    image.image_id = r.Read<uint32_t>("image_id");
    r.SetRecordId(image.image_id);
    if (images.count(image.image_id) != 0) {
      r.Fail("image_id", std::to_string(image.image_id), "duplicate image id", kReexportHint);
    }
    r.ReadDoubles(&image.qvec, "qvec");
    r.ReadDoubles(&image.tvec, "tvec");
    image.camera_id = r.Read<uint32_t>("camera_id");
    image.name = r.ReadName("name");
    const uint64_t num_points = r.ReadCount("num_points2D", kPoint2DBytes, "point2D");
    image.points2D.resize(static_cast<size_t>(num_points));
    for (Point2D& p : image.points2D) {
      p.x = r.Read<double>("points2D x");
      p.y = r.Read<double>("points2D y");
      p.point3D_id = r.Read<uint64_t>("points2D point3D_id");
    }
    images.emplace(image.image_id, std::move(image));
  }
  r.ExpectEnd();
  rec->images = std::move(images);
}

void ReadPoints3DBinary(std::istream& in, const std::string& name, Reconstruction* rec) {
  ByteReader r(in, name, "points3D.bin");
  std::map<uint64_t, Point3D> points;
  const uint64_t n = r.ReadCount("num_points", kMinPoint3DBytes, "point");
  for (uint64_t i = 0; i < n; ++i) {
    r.BeginRecord("point", i + 1);
    Point3D p;
    p.point3D_id = r.Read<uint64_t>("point3D_id");
    r.SetRecordId(p.point3D_id);
    if (points.count(p.point3D_id) != 0) {
      r.Fail("point3D_id", std::to_string(p.point3D_id), "duplicate point3D id", kReexportHint);
    }
    r.ReadDoubles(&p.xyz, "xyz");
    for (uint8_t& c : p.rgb) c = r.Read<uint8_t>("rgb");
    p.error = r.Read<double>("error");
    const uint64_t length = r.ReadCount("track_length", kTrackElementBytes, "track element");
    p.track.resize(static_cast<size_t>(length));
    for (TrackElement& t : p.track) {
      t.image_id = r.Read<uint32_t>("track image_id");
      t.point2D_idx = r.Read<uint32_t>("track point2D_idx");
    }
    points.emplace(p.point3D_id, std::move(p));
  }
  r.ExpectEnd();
  rec->points3D = std::move(points);
}

void WriteCamerasBinary(std::ostream& out, const Reconstruction& rec) {
  PutLE(out, uint64_t{rec.cameras.size()});
  for (const auto& [id, cam] : rec.cameras) {
    ModelForWriting(cam);
    PutLE(out, id, int32_t{cam.model_id}, cam.width, cam.height);
    for (const double v : cam.params) PutLE(out, v);
  }
}

void WriteImagesBinary(std::ostream& out, const Reconstruction& rec) {
  PutLE(out, uint64_t{rec.images.size()});
  for (const auto& [id, image] : rec.images) {
    CheckNameForWriting(image);
    const auto& [qw, qx, qy, qz] = image.qvec;
    const auto& [tx, ty, tz] = image.tvec;
    PutLE(out, id, qw, qx, qy, qz, tx, ty, tz, image.camera_id);
    out.write(image.name.c_str(), static_cast<std::streamsize>(image.name.size() + 1));
    PutLE(out, uint64_t{image.points2D.size()});
    for (const Point2D& p : image.points2D) PutLE(out, p.x, p.y, p.point3D_id);
  }
}

void WritePoints3DBinary(std::ostream& out, const Reconstruction& rec) {
  PutLE(out, uint64_t{rec.points3D.size()});
  for (const auto& [id, p] : rec.points3D) {
    PutLE(out, id, p.xyz[0], p.xyz[1], p.xyz[2], p.rgb[0], p.rgb[1], p.rgb[2], p.error,
          uint64_t{p.track.size()});
    for (const TrackElement& t : p.track) PutLE(out, t.image_id, t.point2D_idx);
  }
}

}  // namespace perf::colmap
