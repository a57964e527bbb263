// COLMAP sparse model I/O in COLMAP's own formats (src/base/reconstruction.cc in 3.8,
// src/colmap/scene/reconstruction_io.cc later): binary files are little-endian, each a uint64
// record count followed by the records; text files hold one record per line (two per image)
// after '#' comment lines.
//
// Binary readers slurp the file and read from memory, so every count is checked against the
// bytes actually left before anything is allocated for it: a flipped bit in a count gives a
// clear error instead of a multi-gigabyte allocation or a long loop.
#include "sfm_import/colmap_model.h"

#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <map>
#include <fstream>
#include <istream>
#include <optional>
#include <ostream>
#include <string_view>
#include <type_traits>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "sfm_import/camera_models.h"

namespace fs = std::filesystem;

namespace perf::colmap {
namespace {

constexpr size_t kMaxNameBytes = 4096;
// Smallest possible records in bytes (layouts in colmap_model.h): a camera with the 3 params of
// SIMPLE_PINHOLE; an image with an empty name and no points.
constexpr uint64_t kMinCameraBytes = 4 + 4 + 8 + 8 + 3 * 8;
constexpr uint64_t kMinImageBytes = 4 + 4 * 8 + 3 * 8 + 4 + 1 + 8;
constexpr uint64_t kPoint2DBytes = 8 + 8 + 8;
constexpr uint64_t kMinPoint3DBytes = 8 + 3 * 8 + 3 + 8 + 8;
constexpr uint64_t kTrackElementBytes = 4 + 4;
// No real camera has a side this long; larger values are corruption, and later stages would
// allocate width * height pixels.
constexpr uint64_t kMaxImageSide = uint64_t{1} << 20;

constexpr const char* kModelIdHint =
    "COLMAP model ids are 0-11: SIMPLE_PINHOLE=0, PINHOLE=1, SIMPLE_RADIAL=2, RADIAL=3, "
    "OPENCV=4, OPENCV_FISHEYE=5, FULL_OPENCV=6, FOV=7, SIMPLE_RADIAL_FISHEYE=8, "
    "RADIAL_FISHEYE=9, THIN_PRISM_FISHEYE=10, RAD_TAN_THIN_PRISM_FISHEYE=11";
constexpr const char* kModelNameHint =
    "COLMAP models are SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE, "
    "FULL_OPENCV, FOV, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE, THIN_PRISM_FISHEYE, "
    "RAD_TAN_THIN_PRISM_FISHEYE";
constexpr const char* kReexportHint =
    "re-export the model from COLMAP (colmap model_converter --output_type BIN) instead of "
    "editing or generating it by hand";
constexpr const char* kMismatchHint =
    "the model's files do not belong together; re-export the model from COLMAP (colmap "
    "model_converter) so cameras, images and points3D come from one reconstruction";
constexpr const char* kFolderHint =
    "point --colmap at the folder that holds cameras, images and points3D (.bin or .txt), "
    "e.g. sparse/0";

// A possibly hostile string made safe for messages: control bytes escaped, cut short.
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

// Why an image name cannot be used, or "". Names are relative paths joined to the image folder
// later; control characters (such as the newline that would break images.txt) are never part
// of a real file name.
std::string NameProblem(std::string_view name) {
  if (name.empty()) return "empty image name";
  if (name.size() > kMaxNameBytes) return StrCat("longer than ", kMaxNameBytes, " bytes");
  for (const char c : name) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) return "contains a control character";
  }
  return {};
}

std::string ListValues(const auto& values) {
  std::string s;
  for (const double v : values) s += StrCat(s.empty() ? "" : " ", v);
  return s;
}

bool AllFinite(const auto& values) {
  for (const double v : values) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

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

// ---------------------------------------------------------------------------------------------
// Text reading and writing.

constexpr std::string_view kSpace = " \t\r\n\v\f";

std::string_view Trim(std::string_view s) {
  const size_t b = s.find_first_not_of(kSpace);
  if (b == std::string_view::npos) return {};
  return s.substr(b, s.find_last_not_of(kSpace) - b + 1);
}

// A field name for messages, formatted only when an error is thrown (a text model has millions
// of fields): "POINTS2D[5] X" is {"POINTS2D", 5, "X"}.
struct FieldName {
  FieldName(const char* n) : name(n) {}  // implicit: plain names are literals
  FieldName(const char* n, size_t i, const char* s) : name(n), index(i), sub(s) {}
  std::string Format() const {
    return index == kNone ? std::string(name) : StrCat(name, "[", index, "]", *sub ? " " : "", sub);
  }
  static constexpr size_t kNone = static_cast<size_t>(-1);
  const char* name;
  size_t index = kNone;
  const char* sub = "";
};

// Reads a text file line by line and splits lines on whitespace. Errors carry file:line, the
// record ("image 7"), the field and the offending token, and repeat the expected layout.
class TextReader {
 public:
  TextReader(std::istream& in, const std::string& name, const char* layout)
      : in_(in), name_(name), layout_(layout) {}

  // Loads the next line; record lines skip blank and '#' lines as COLMAP's readers do.
  bool NextLine(bool skip_blank_and_comments) {
    context_.clear();
    while (std::getline(in_, line_)) {
      ++line_no_;
      pos_ = 0;
      const std::string_view t = Trim(line_);
      if (!skip_blank_and_comments || (!t.empty() && t[0] != '#')) return true;
    }
    if (in_.bad()) throw IoError(name_, "read failed");
    return false;
  }

  void SetContext(std::string context) { context_ = std::move(context); }
  std::string_view Rest() const { return Trim(std::string_view(line_).substr(pos_)); }

  std::optional<std::string_view> NextToken() {
    const std::string_view line(line_);
    const size_t b = line.find_first_not_of(kSpace, pos_);
    if (b == std::string_view::npos) {
      pos_ = line.size();
      return std::nullopt;
    }
    pos_ = std::min(line.find_first_of(kSpace, b), line.size());
    return line.substr(b, pos_ - b);
  }

  std::string_view Token(const FieldName& field) {
    const auto token = NextToken();
    if (!token) Fail(field, "", "missing (the line ends early)");
    return *token;
  }

  template <typename T>
  T Parse(const FieldName& field) {
    return ParseToken<T>(Token(field), field);
  }

  // The whole token as T (an unsigned integer or a double), via the locale-free from_chars.
  template <typename T>
  T ParseToken(std::string_view token, const FieldName& field) const {
    std::string_view s = token;
    if (s.size() > 1 && s[0] == '+' && s[1] != '-') s.remove_prefix(1);  // from_chars rejects +
    T value{};
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
    if (ec == std::errc::result_out_of_range) Fail(field, token, "number out of range");
    if (ec != std::errc() || end != s.data() + s.size()) {
      Fail(field, token,
           std::is_floating_point_v<T> ? "not a number" : "not a non-negative integer");
    }
    return value;
  }

  [[noreturn]] void Fail(const FieldName& field, std::string_view value, const std::string& problem,
                         const char* hint = nullptr) const {
    throw InputError(Where(), context_.empty() ? field.Format() : context_ + " " + field.Format(),
                     Printable(value), problem,
                     hint != nullptr ? std::string(hint) : StrCat("expected: ", layout_));
  }

  std::string Where() const { return StrCat(name_, ":", line_no_); }

 private:
  std::istream& in_;
  const std::string& name_;
  const char* layout_;
  std::string line_, context_;
  size_t pos_ = 0;
  uint64_t line_no_ = 0;
};

// Builds space-separated lines, independent of the locale. Doubles get 17 significant digits
// ("%.17g", as COLMAP writes them): the shortest round-trip form is not enough, because COLMAP
// reads text with std::stold and then rounds to double, and that double rounding can miss the
// original when the shortest decimal lies near the midpoint between two doubles.
struct TextRow {
  template <typename T>
  TextRow& operator<<(const T& v) {
    if (!s.empty() && s.back() != '\n') s += ' ';
    char buf[64];
    if constexpr (std::is_floating_point_v<T>) {
      s.append(buf, std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 17).ptr);
    } else if constexpr (std::is_integral_v<T>) {
      s.append(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
    } else {
      s += v;
    }
    return *this;
  }
  void EndLine() { s += '\n'; }
  std::string s;
};

// Writers take a model built in memory, so inconsistencies there are our bugs, not input errors.
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

// ---------------------------------------------------------------------------------------------
// Text readers and writers.

void ReadCamerasText(std::istream& in, const std::string& name, Reconstruction* rec) {
  TextReader r(in, name, "CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
  std::map<uint32_t, Camera> cameras;
  while (r.NextLine(true)) {
    Camera cam;
    cam.camera_id = r.Parse<uint32_t>("CAMERA_ID");
    r.SetContext(StrCat("camera ", cam.camera_id));
    if (cameras.count(cam.camera_id) != 0) {
      r.Fail("CAMERA_ID", std::to_string(cam.camera_id), "duplicate camera id", kReexportHint);
    }
    const std::string_view model_name = r.Token("MODEL");
    const CameraModelInfo* model = FindCameraModel(model_name);
    if (model == nullptr) r.Fail("MODEL", model_name, "unknown camera model", kModelNameHint);
    cam.model_id = static_cast<int>(model->id);
    cam.width = r.Parse<uint64_t>("WIDTH");
    cam.height = r.Parse<uint64_t>("HEIGHT");
    while (const auto token = r.NextToken()) {
      cam.params.push_back(r.ParseToken<double>(*token, {"PARAMS", cam.params.size(), ""}));
    }
    if (static_cast<int>(cam.params.size()) != model->num_params) {
      const std::string hint = StrCat("model ", model->name, " takes ", model->num_params,
                                      " parameters: ", model->params);
      r.Fail("PARAMS", StrCat(cam.params.size(), " values"), "wrong number of parameters",
             hint.c_str());
    }
    cameras.emplace(cam.camera_id, std::move(cam));
  }
  rec->cameras = std::move(cameras);
}

void ReadImagesText(std::istream& in, const std::string& name, Reconstruction* rec) {
  TextReader r(in, name,
               "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then a line of X Y POINT3D_ID "
               "triples (possibly empty)");
  std::map<uint32_t, Image> images;
  // Two lines per image. The second may be empty, so only the first skips blank lines.
  while (r.NextLine(true)) {
    Image image;
    image.image_id = r.Parse<uint32_t>("IMAGE_ID");
    const std::string context = StrCat("image ", image.image_id);
    r.SetContext(context);
    if (images.count(image.image_id) != 0) {
      r.Fail("IMAGE_ID", std::to_string(image.image_id), "duplicate image id", kReexportHint);
    }
    constexpr const char* kPose[] = {"QW", "QX", "QY", "QZ", "TX", "TY", "TZ"};
    for (size_t k = 0; k < 4; ++k) image.qvec[k] = r.Parse<double>(kPose[k]);
    for (size_t k = 0; k < 3; ++k) image.tvec[k] = r.Parse<double>(kPose[4 + k]);
    image.camera_id = r.Parse<uint32_t>("CAMERA_ID");
    // The name is the rest of the line, so names with spaces survive (COLMAP writes them raw).
    image.name = std::string(r.Rest());
    if (image.name.empty()) r.Fail("NAME", "", "missing (the line ends early)");
    if (const std::string problem = NameProblem(image.name); !problem.empty()) {
      r.Fail("NAME", image.name, problem);
    }

    // A file that ends right after an image's first line holds no points for it.
    if (r.NextLine(false)) {
      r.SetContext(context);
      while (const auto x = r.NextToken()) {
        const size_t k = image.points2D.size();
        Point2D& p = image.points2D.emplace_back();
        p.x = r.ParseToken<double>(*x, {"POINTS2D", k, "X"});
        p.y = r.Parse<double>({"POINTS2D", k, "Y"});
        const FieldName id_field("POINTS2D", k, "POINT3D_ID");
        const std::string_view id = r.Token(id_field);
        // COLMAP writes -1 for "no 3D point".
        p.point3D_id = id == "-1" ? kInvalidPoint3DId : r.ParseToken<uint64_t>(id, id_field);
      }
    }
    images.emplace(image.image_id, std::move(image));
  }
  rec->images = std::move(images);
}

void ReadPoints3DText(std::istream& in, const std::string& name, Reconstruction* rec) {
  TextReader r(in, name, "POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)");
  std::map<uint64_t, Point3D> points;
  while (r.NextLine(true)) {
    Point3D p;
    p.point3D_id = r.Parse<uint64_t>("POINT3D_ID");
    r.SetContext(StrCat("point ", p.point3D_id));
    if (points.count(p.point3D_id) != 0) {
      r.Fail("POINT3D_ID", std::to_string(p.point3D_id), "duplicate point3D id", kReexportHint);
    }
    constexpr const char* kFields[] = {"X", "Y", "Z", "R", "G", "B"};
    for (size_t k = 0; k < 3; ++k) p.xyz[k] = r.Parse<double>(kFields[k]);
    for (size_t k = 0; k < 3; ++k) {
      const std::string_view token = r.Token(kFields[3 + k]);
      const auto v = r.ParseToken<uint32_t>(token, kFields[3 + k]);
      if (v > 255) r.Fail(kFields[3 + k], token, "colour out of range 0-255");
      p.rgb[k] = static_cast<uint8_t>(v);
    }
    p.error = r.Parse<double>("ERROR");
    while (const auto image_id = r.NextToken()) {
      const size_t k = p.track.size();
      TrackElement& t = p.track.emplace_back();
      t.image_id = r.ParseToken<uint32_t>(*image_id, {"TRACK", k, "IMAGE_ID"});
      t.point2D_idx = r.Parse<uint32_t>({"TRACK", k, "POINT2D_IDX"});
    }
    points.emplace(p.point3D_id, std::move(p));
  }
  rec->points3D = std::move(points);
}

// The text writers produce COLMAP's own headers, so the files are interchangeable with its.
void WriteCamerasText(std::ostream& out, const Reconstruction& rec) {
  out << "# Camera list with one line of data per camera:\n"
         "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
         "# Number of cameras: "
      << rec.cameras.size() << "\n";
  for (const auto& [id, cam] : rec.cameras) {
    TextRow row;
    row << id << ModelForWriting(cam).name << cam.width << cam.height;
    for (const double v : cam.params) row << v;
    row.EndLine();
    out << row.s;
  }
}

void WriteImagesText(std::ostream& out, const Reconstruction& rec) {
  uint64_t observations = 0;
  for (const auto& [id, image] : rec.images) {
    for (const Point2D& p : image.points2D) observations += p.point3D_id != kInvalidPoint3DId;
  }
  TextRow mean;
  mean << (rec.images.empty() ? 0.0 : double(observations) / double(rec.images.size()));
  out << "# Image list with two lines of data per image:\n"
         "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
         "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
         "# Number of images: "
      << rec.images.size() << ", mean observations per image: " << mean.s << "\n";
  for (const auto& [id, image] : rec.images) {
    CheckNameForWriting(image);
    TextRow row;
    row << id;
    for (const double v : image.qvec) row << v;
    for (const double v : image.tvec) row << v;
    row << image.camera_id << image.name;
    row.EndLine();
    for (const Point2D& p : image.points2D) {
      row << p.x << p.y;
      if (p.point3D_id == kInvalidPoint3DId) {
        row << "-1";  // COLMAP's "no 3D point"
      } else {
        row << p.point3D_id;
      }
    }
    row.EndLine();
    out << row.s;
  }
}

void WritePoints3DText(std::ostream& out, const Reconstruction& rec) {
  uint64_t elements = 0;
  for (const auto& [id, p] : rec.points3D) elements += p.track.size();
  TextRow mean;
  mean << (rec.points3D.empty() ? 0.0 : double(elements) / double(rec.points3D.size()));
  out << "# 3D point list with one line of data per point:\n"
         "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
         "# Number of points: "
      << rec.points3D.size() << ", mean track length: " << mean.s << "\n";
  for (const auto& [id, p] : rec.points3D) {
    TextRow row;
    row << id << p.xyz[0] << p.xyz[1] << p.xyz[2];
    for (const uint8_t c : p.rgb) row << static_cast<unsigned>(c);
    row << p.error;
    for (const TrackElement& t : p.track) row << t.image_id << t.point2D_idx;
    row.EndLine();
    out << row.s;
  }
}

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

// The files of `files` that are not in `dir`, comma separated.
std::string Missing(const fs::path& dir, const char* const (&files)[3]) {
  std::string missing;
  for (const char* f : files) {
    std::error_code ec;
    if (!fs::is_regular_file(dir / f, ec)) missing += StrCat(missing.empty() ? "" : ", ", f);
  }
  return missing;
}

void ReadFile(const fs::path& path,
              void (*read)(std::istream&, const std::string&, Reconstruction*),
              Reconstruction* rec) {
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
