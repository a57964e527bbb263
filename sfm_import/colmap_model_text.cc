// COLMAP's text model files: one record per line (two per image) after '#' comment lines, and
// COLMAP's own headers on writing, so the files are interchangeable with its.
#include <charconv>
#include <cmath>
#include <istream>
#include <optional>
#include <ostream>
#include <string_view>

#include "common/errors.h"
#include "sfm_import/colmap_model.h"
#include "sfm_import/colmap_model_common.h"

namespace perf::colmap {

using namespace detail;

namespace {

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

}  // namespace

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

}  // namespace perf::colmap
