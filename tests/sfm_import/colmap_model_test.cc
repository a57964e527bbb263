// COLMAP model I/O: round trips in both formats, agreement with the real `colmap` binary on
// the bonsai scene, and bad input of every kind (each must give InputError naming the file,
// the field and the value, never a crash).
#include "sfm_import/colmap_model.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <random>
#include <sstream>

#include "common/errors.h"
#include "sfm_import/camera_models.h"

namespace perf::colmap {
namespace {

namespace fs = std::filesystem;

// A fresh folder under the system temp dir, removed with its contents at the end of the test.
class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    path_ = fs::temp_directory_path() / StrCat("perf_colmap_model_test_", ::getpid(), "_",
                                               counter++, "_", std::random_device{}());
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

Camera MakeCamera(uint32_t id, CameraModelId model, uint64_t width, uint64_t height) {
  Camera cam;
  cam.camera_id = id;
  cam.model_id = static_cast<int>(model);
  cam.width = width;
  cam.height = height;
  const int n = FindCameraModel(cam.model_id)->num_params;
  // Values that need all 17 significant digits, plus a few extremes.
  for (int k = 0; k < n; ++k)
    cam.params.push_back((k < 4 ? 500.0 : 0.01) * (1.0 + k / 7.0) + id / 3.0);
  if (n > 5) cam.params[4] = -1e-300;
  if (n > 6) cam.params[5] = -0.0;
  return cam;
}

std::array<double, 4> UnitQuaternion(double w, double x, double y, double z) {
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  return {w / n, x / n, y / n, z / n};
}

// A small model covering every camera model (including ones PERF cannot undistort, which must
// still read), sparse ids up to the type limits, names with folders and spaces, points2D with
// and without 3D points, and an image with no points at all.
Reconstruction MakeReconstruction() {
  Reconstruction rec;
  uint32_t cam_id = 1;
  for (const CameraModelId model :
       {CameraModelId::kOpenCV, CameraModelId::kFullOpenCV, CameraModelId::kOpenCVFisheye,
        CameraModelId::kSimpleRadialFisheye, CameraModelId::kRadialFisheye, CameraModelId::kFOV,
        CameraModelId::kThinPrismFisheye, CameraModelId::kRadTanThinPrismFisheye,
        CameraModelId::kSimplePinhole, CameraModelId::kPinhole}) {
    rec.cameras[cam_id] = MakeCamera(cam_id, model, 800 + cam_id, 533 + cam_id);
    cam_id = cam_id * 3 + 1;
  }
  const auto add_image = [&](uint32_t id, uint32_t camera, std::string name,
                             std::array<double, 4> q, std::array<double, 3> t, int points) {
    Image image;
    image.image_id = id;
    image.camera_id = camera;
    image.name = std::move(name);
    image.qvec = q;
    image.tvec = t;
    for (int k = 0; k < points; ++k) {
      image.points2D.push_back(
          {0.5 + k / 3.0, 799.5 - k * 0.1, k % 3 == 2 ? kInvalidPoint3DId : uint64_t(k)});
    }
    rec.images[id] = image;
  };
  add_image(1, 1, "DSC_0001.JPG", UnitQuaternion(0.3, -0.5, 0.7, 0.1),
            {-0.68682736597186289, 1.0 / 3.0, 2.8}, 5);
  add_image(7, 4, "sub dir/img 7.png", UnitQuaternion(1, 1e-9, 0, -1e-9), {0, -0.0, 1e10}, 3);
  add_image(42, 364, "fov/unsupported.jpg", UnitQuaternion(-0.2, 0.1, 0.9, 0.3), {1, 2, 3}, 0);
  add_image(std::numeric_limits<uint32_t>::max(), 3280, "x", {1, 0, 0, 0}, {5e-324, 0, 0}, 2);

  const auto add_point = [&](uint64_t id, std::array<double, 3> xyz, std::array<uint8_t, 3> rgb,
                             double error, std::vector<TrackElement> track) {
    rec.points3D[id] = Point3D{id, xyz, rgb, error, std::move(track)};
  };
  add_point(0, {-10.994138382049808, 11.198083944866612, 5.4905160330406719}, {0, 128, 255},
            0.69143169737992471, {{1, 0}, {7, 0}, {std::numeric_limits<uint32_t>::max(), 0}});
  add_point(1, {1.0 / 3.0, -2.0 / 3.0, 1e-300}, {1, 2, 3}, -1, {{1, 1}, {7, 1}});
  add_point(std::numeric_limits<uint64_t>::max() - 1, {0, 0, 0}, {255, 255, 255}, 0, {});
  return rec;
}

// Compares everything; doubles within `rel` relative error (0: exactly equal). Stops at the
// first difference so a large model does not flood the log.
::testing::AssertionResult SameReconstruction(const Reconstruction& a, const Reconstruction& b,
                                              double rel = 0) {
  std::string where;
  const auto same = [&](double x, double y) {
    return x == y || (std::isnan(x) && std::isnan(y)) ||
           std::abs(x - y) <= rel * std::max(std::abs(x), std::abs(y));
  };
  const auto fail = [&](const std::string& what) {
    return ::testing::AssertionFailure() << where << ": " << what << " differs";
  };
  if (a.cameras.size() != b.cameras.size()) return fail("number of cameras");
  if (a.images.size() != b.images.size()) return fail("number of images");
  if (a.points3D.size() != b.points3D.size()) return fail("number of points3D");
  for (const auto& [id, ca] : a.cameras) {
    where = StrCat("camera ", id);
    if (b.cameras.count(id) == 0) return fail("presence");
    const Camera& cb = b.cameras.at(id);
    if (ca.camera_id != cb.camera_id || ca.model_id != cb.model_id) return fail("id or model");
    if (ca.width != cb.width || ca.height != cb.height) return fail("size");
    if (ca.params.size() != cb.params.size()) return fail("params count");
    for (size_t k = 0; k < ca.params.size(); ++k) {
      if (!same(ca.params[k], cb.params[k])) return fail(StrCat("params[", k, "]"));
    }
  }
  for (const auto& [id, ia] : a.images) {
    where = StrCat("image ", id);
    if (b.images.count(id) == 0) return fail("presence");
    const Image& ib = b.images.at(id);
    if (ia.image_id != ib.image_id || ia.camera_id != ib.camera_id) return fail("id or camera");
    if (ia.name != ib.name) return fail("name");
    for (size_t k = 0; k < 4; ++k) {
      if (!same(ia.qvec[k], ib.qvec[k])) return fail(StrCat("qvec[", k, "]"));
    }
    for (size_t k = 0; k < 3; ++k) {
      if (!same(ia.tvec[k], ib.tvec[k])) return fail(StrCat("tvec[", k, "]"));
    }
    if (ia.points2D.size() != ib.points2D.size()) return fail("points2D count");
    for (size_t k = 0; k < ia.points2D.size(); ++k) {
      const Point2D &pa = ia.points2D[k], &pb = ib.points2D[k];
      if (!same(pa.x, pb.x) || !same(pa.y, pb.y) || pa.point3D_id != pb.point3D_id) {
        return fail(StrCat("points2D[", k, "]"));
      }
    }
  }
  for (const auto& [id, pa] : a.points3D) {
    where = StrCat("point3D ", id);
    if (b.points3D.count(id) == 0) return fail("presence");
    const Point3D& pb = b.points3D.at(id);
    if (pa.point3D_id != pb.point3D_id || pa.rgb != pb.rgb) return fail("id or colour");
    for (size_t k = 0; k < 3; ++k) {
      if (!same(pa.xyz[k], pb.xyz[k])) return fail(StrCat("xyz[", k, "]"));
    }
    if (!same(pa.error, pb.error)) return fail("error");
    if (pa.track.size() != pb.track.size()) return fail("track length");
    for (size_t k = 0; k < pa.track.size(); ++k) {
      if (pa.track[k].image_id != pb.track[k].image_id ||
          pa.track[k].point2D_idx != pb.track[k].point2D_idx) {
        return fail(StrCat("track[", k, "]"));
      }
    }
  }
  return ::testing::AssertionSuccess();
}

using Writer = void (*)(std::ostream&, const Reconstruction&);
using Reader = void (*)(std::istream&, const std::string&, Reconstruction*);

std::string Serialize(Writer write, const Reconstruction& rec) {
  std::ostringstream out;
  write(out, rec);
  return out.str();
}

void Parse(Reader read, const std::string& bytes, const std::string& name, Reconstruction* rec) {
  std::istringstream in(bytes);
  read(in, name, rec);
}

// Runs `fn`, which must throw E; returns its message (empty, with a test failure, otherwise).
template <typename E = InputError, typename Fn>
std::string MessageOf(Fn&& fn) {
  try {
    fn();
  } catch (const E& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
    return {};
  }
  ADD_FAILURE() << "no exception thrown";
  return {};
}

void ExpectContains(const std::string& message, std::initializer_list<const char*> parts) {
  for (const char* part : parts) {
    EXPECT_NE(message.find(part), std::string::npos)
        << "message \"" << message << "\" lacks \"" << part << "\"";
  }
}
// Evaluates `message` once and checks that it holds every part.
#define EXPECT_CONTAINS(message, ...)       \
  do {                                      \
    SCOPED_TRACE("EXPECT_CONTAINS");        \
    ExpectContains(message, {__VA_ARGS__}); \
  } while (0)

template <typename T>
void PatchLE(std::string* bytes, size_t offset, T value) {
  const auto u = std::bit_cast<std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>>(value);
  for (size_t i = 0; i < sizeof(T); ++i) (*bytes)[offset + i] = static_cast<char>(u >> (8 * i));
}

std::string U64(uint64_t v) {
  std::string s(8, '\0');
  PatchLE(&s, 0, v);
  return s;
}

// ---------------------------------------------------------------------------------------------
// Round trips.

TEST(ColmapModel, HandBuiltModelIsValid) {
  EXPECT_NO_THROW(ValidateReconstruction(MakeReconstruction(), "hand-built"));
}

TEST(ColmapModel, BinaryStreamRoundTripIsExact) {
  const Reconstruction rec = MakeReconstruction();
  Reconstruction back;
  Parse(ReadCamerasBinary, Serialize(WriteCamerasBinary, rec), "cameras.bin", &back);
  Parse(ReadImagesBinary, Serialize(WriteImagesBinary, rec), "images.bin", &back);
  Parse(ReadPoints3DBinary, Serialize(WritePoints3DBinary, rec), "points3D.bin", &back);
  EXPECT_TRUE(SameReconstruction(rec, back));
  EXPECT_TRUE(std::signbit(back.cameras.at(4).params[5]));  // -0.0 kept
  EXPECT_EQ(Serialize(WriteImagesBinary, back), Serialize(WriteImagesBinary, rec));
}

TEST(ColmapModel, BinaryLayoutIsColmaps) {
  Reconstruction rec;
  rec.cameras[3] = MakeCamera(3, CameraModelId::kSimplePinhole, 640, 480);
  const std::string bytes = Serialize(WriteCamerasBinary, rec);
  ASSERT_EQ(bytes.size(), 8u + 4 + 4 + 8 + 8 + 3 * 8);
  EXPECT_EQ(bytes.substr(0, 8), U64(1));
  EXPECT_EQ(bytes.substr(8, 8), std::string("\x03\0\0\0\0\0\0\0", 8));  // id 3, SIMPLE_PINHOLE=0
  EXPECT_EQ(bytes.substr(16, 8), U64(640));
}

TEST(ColmapModel, TextStreamRoundTripIsExact) {
  const Reconstruction rec = MakeReconstruction();
  Reconstruction back;
  Parse(ReadCamerasText, Serialize(WriteCamerasText, rec), "cameras.txt", &back);
  Parse(ReadImagesText, Serialize(WriteImagesText, rec), "images.txt", &back);
  Parse(ReadPoints3DText, Serialize(WritePoints3DText, rec), "points3D.txt", &back);
  // Full precision: every double reads back bit for bit.
  EXPECT_TRUE(SameReconstruction(rec, back));
  EXPECT_TRUE(std::signbit(back.cameras.at(4).params[5]));
}

TEST(ColmapModel, TextUsesColmapHeadersNamesAndMinusOne) {
  const Reconstruction rec = MakeReconstruction();
  const std::string cameras = Serialize(WriteCamerasText, rec);
  EXPECT_EQ(cameras.rfind("# Camera list with one line of data per camera:\n"
                          "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                          "# Number of cameras: 10\n1 OPENCV 801 534 ",
                          0),
            0u);
  EXPECT_NE(cameras.find(" FOV "), std::string::npos);
  const std::string images = Serialize(WriteImagesText, rec);
  EXPECT_EQ(images.rfind("# Image list with two lines of data per image:\n"
                         "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                         "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
                         "# Number of images: 4, mean observations per image: 2\n",
                         0),
            0u);
  EXPECT_NE(images.find(" 1 DSC_0001.JPG\n0.5 799.5 0 "), std::string::npos);
  EXPECT_NE(images.find(" -1 "), std::string::npos);
  EXPECT_NE(images.find("fov/unsupported.jpg\n\n"), std::string::npos);  // empty points line
  const std::string points = Serialize(WritePoints3DText, rec);
  EXPECT_EQ(
      points.rfind("# 3D point list with one line of data per point:\n"
                   "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, "
                   "POINT2D_IDX)\n# Number of points: 3, mean track length: 1.6666666666666667\n",
                   0),
      0u);
  EXPECT_NE(points.find("0 -10.994138382049808 11.198083944866612 5.4905160330406719 0 128 255 "),
            std::string::npos);
}

TEST(ColmapModel, TextReadersAcceptCrlfBlankLinesAndMissingLastLine) {
  Reconstruction rec;
  Parse(ReadCamerasText, "# c\r\n\r\n1 PINHOLE 10 20 1 2 3 4\r\n", "cameras.txt", &rec);
  Parse(ReadImagesText, "# i\r\n1 1 0 0 0 0 0 0 1 a.jpg\r\n\r\n2 1 0 0 0 0 0 0 1 b.jpg",
        "images.txt", &rec);
  Parse(ReadPoints3DText, "", "points3D.txt", &rec);
  ASSERT_EQ(rec.images.size(), 2u);
  EXPECT_EQ(rec.images.at(1).name, "a.jpg");
  EXPECT_TRUE(rec.images.at(2).points2D.empty());
  EXPECT_EQ(rec.cameras.at(1).params, (std::vector<double>{1, 2, 3, 4}));
  EXPECT_NO_THROW(ValidateReconstruction(rec, "crlf"));
}

TEST(ColmapModel, PathRoundTripInBothFormats) {
  const Reconstruction rec = MakeReconstruction();
  for (const ModelFormat format : {ModelFormat::kBinary, ModelFormat::kText}) {
    TempDir tmp;
    const fs::path dir = tmp.path() / "sparse" / "0";  // created by the writer
    WriteReconstruction(dir, rec, format);
    EXPECT_EQ(DetectModelFormat(dir), format);
    EXPECT_TRUE(SameReconstruction(rec, ReadReconstruction(dir)));
    int files = 0;
    for ([[maybe_unused]] const auto& entry : fs::directory_iterator(dir)) ++files;
    EXPECT_EQ(files, 3) << "temporary files left behind";
    // Overwriting keeps working (atomic rename over the old file).
    WriteReconstruction(dir, rec, format);
    EXPECT_TRUE(SameReconstruction(rec, ReadReconstruction(dir)));
  }
}

// ---------------------------------------------------------------------------------------------
// The real COLMAP: bonsai's model as COLMAP wrote it, and COLMAP's conversions.

const fs::path kBonsai = fs::path(PERF_SHARED_DATA_DIR) / "bonsai" / "sparse" / "0";

bool HaveColmap() { return std::system("command -v colmap > /dev/null 2>&1") == 0; }

// Runs `colmap model_converter` headless; fails the test with COLMAP's output if it fails.
::testing::AssertionResult ColmapConvert(const fs::path& in, const fs::path& out,
                                         const char* type) {
  fs::create_directories(out);
  const fs::path log = out.parent_path() / "colmap.log";
  const std::string cmd = StrCat("QT_QPA_PLATFORM=offscreen colmap model_converter --input_path '",
                                 in.string(), "' --output_path '", out.string(), "' --output_type ",
                                 type, " > '", log.string(), "' 2>&1");
  if (std::system(cmd.c_str()) == 0) return ::testing::AssertionSuccess();
  std::ifstream f(log);
  std::stringstream text;
  text << f.rdbuf();
  return ::testing::AssertionFailure() << cmd << " failed:\n" << text.str();
}

#define REQUIRE_BONSAI()                                           \
  if (!fs::is_regular_file(kBonsai / "images.bin")) {              \
    GTEST_SKIP() << "bonsai COLMAP model not found at " << kBonsai \
                 << " (shared test data; see scripts/setup.sh)";   \
  }
#define REQUIRE_COLMAP() \
  if (!HaveColmap()) GTEST_SKIP() << "the colmap binary is not on PATH (apt install colmap)";

TEST(ColmapModelBonsai, Facts) {
  REQUIRE_BONSAI();
  const Reconstruction rec = ReadReconstruction(kBonsai);
  ASSERT_EQ(rec.cameras.size(), 1u);
  const Camera& cam = rec.cameras.begin()->second;
  EXPECT_EQ(cam.model_id, static_cast<int>(CameraModelId::kOpenCV));
  EXPECT_EQ(cam.width, 800u);
  EXPECT_EQ(cam.height, 533u);
  EXPECT_EQ(rec.images.size(), 84u);
  EXPECT_EQ(rec.points3D.size(), 29745u);
  EXPECT_EQ(rec.images.at(84).name, "DSCF5854.JPG");
}

TEST(ColmapModelBonsai, BinaryMatchesColmapsTextExport) {
  REQUIRE_BONSAI();
  REQUIRE_COLMAP();
  TempDir tmp;
  const fs::path txt = tmp.path() / "txt";
  ASSERT_TRUE(ColmapConvert(kBonsai, txt, "TXT"));
  ASSERT_EQ(DetectModelFormat(txt), ModelFormat::kText);
  const Reconstruction rec = ReadReconstruction(kBonsai);
  EXPECT_TRUE(SameReconstruction(rec, ReadReconstruction(txt), 1e-9));
  // Same digits as COLMAP (17 significant): our cameras.txt is byte for byte COLMAP's.
  std::ifstream colmap_cameras(txt / "cameras.txt");
  std::stringstream expected;
  expected << colmap_cameras.rdbuf();
  EXPECT_EQ(Serialize(WriteCamerasText, rec), expected.str());
}

TEST(ColmapModelBonsai, ColmapReadsOurText) {
  REQUIRE_BONSAI();
  REQUIRE_COLMAP();
  TempDir tmp;
  const Reconstruction rec = ReadReconstruction(kBonsai);
  WriteReconstruction(tmp.path() / "ours", rec, ModelFormat::kText);
  const fs::path bin = tmp.path() / "bin";
  ASSERT_TRUE(ColmapConvert(tmp.path() / "ours", bin, "BIN"));
  ASSERT_EQ(DetectModelFormat(bin), ModelFormat::kBinary);
  Reconstruction back = ReadReconstruction(bin);
  // COLMAP renormalises quaternions when it reads a model (its own BIN -> TXT -> BIN changes a
  // few by an ulp too); everything else must come back bit for bit.
  for (auto& [id, image] : back.images) {
    if (rec.images.count(id) == 0) continue;
    for (size_t k = 0; k < 4; ++k) EXPECT_NEAR(image.qvec[k], rec.images.at(id).qvec[k], 1e-15);
    image.qvec = rec.images.at(id).qvec;
  }
  EXPECT_TRUE(SameReconstruction(rec, back));
}

// ---------------------------------------------------------------------------------------------
// Bad binary input.

struct BinaryFile {
  const char* name;
  Writer write;
  Reader read;
};
const BinaryFile kBinaryFiles[] = {
    {"sparse/0/cameras.bin", WriteCamerasBinary, ReadCamerasBinary},
    {"sparse/0/images.bin", WriteImagesBinary, ReadImagesBinary},
    {"sparse/0/points3D.bin", WritePoints3DBinary, ReadPoints3DBinary}};

TEST(ColmapModelBadInput, TruncatedBinaryAtEveryLength) {
  const Reconstruction rec = MakeReconstruction();
  for (const BinaryFile& file : kBinaryFiles) {
    const std::string bytes = Serialize(file.write, rec);
    for (size_t len = 0; len < bytes.size(); ++len) {
      SCOPED_TRACE(StrCat(file.name, " cut to ", len, " of ", bytes.size(), " bytes"));
      Reconstruction out;
      const std::string msg =
          MessageOf([&] { Parse(file.read, bytes.substr(0, len), file.name, &out); });
      EXPECT_CONTAINS(msg, file.name);
      const bool explained = msg.find("file ends early (truncated?)") != std::string::npos ||
                             msg.find("count disagrees with file size") != std::string::npos ||
                             msg.find("no terminating NUL") != std::string::npos;
      EXPECT_TRUE(explained) << msg;
      EXPECT_TRUE(out.cameras.empty() && out.images.empty() && out.points3D.empty());
    }
  }
}

TEST(ColmapModelBadInput, TruncationNamesRecordAndField) {
  Reconstruction rec = MakeReconstruction();
  rec.images.erase(42);
  rec.images.erase(std::numeric_limits<uint32_t>::max());
  const std::string bytes = Serialize(WriteImagesBinary, rec);
  // Image #1 (id 1): 4 + 7*8 + 4 bytes, "DSC_0001.JPG\0", 8 + 5*24 bytes of points.
  const size_t second = 8 + 64 + 13 + 8 + 5 * 24;
  const std::string msg = MessageOf([&] {
    Reconstruction out;
    Parse(ReadImagesBinary, bytes.substr(0, second + 4 + 12), "sparse/0/images.bin", &out);
  });
  EXPECT_CONTAINS(msg, "sparse/0/images.bin: image #2 (id 7) qvec: file ends early (truncated?)");
}

TEST(ColmapModelBadInput, CountsThatDisagreeWithFileSize) {
  const Reconstruction rec = MakeReconstruction();
  Reconstruction out;
  std::string cameras = Serialize(WriteCamerasBinary, rec);
  PatchLE(&cameras, 0, uint64_t{1} << 60);
  EXPECT_CONTAINS(MessageOf([&] { Parse(ReadCamerasBinary, cameras, "c.bin", &out); }), "c.bin",
                  "num_cameras = 1152921504606846976", "count disagrees with file size");

  std::string images = Serialize(WriteImagesBinary, rec);
  PatchLE(&images, 8 + 64 + 13, uint64_t{1} << 61);  // image #1's num_points2D
  EXPECT_CONTAINS(MessageOf([&] { Parse(ReadImagesBinary, images, "i.bin", &out); }),
                  "i.bin: image #1 (id 1) num_points2D = 2305843009213693952",
                  "count disagrees with file size");

  std::string points = Serialize(WritePoints3DBinary, rec);
  PatchLE(&points, 8 + 43, std::numeric_limits<uint64_t>::max());  // point #1's track_length
  EXPECT_CONTAINS(MessageOf([&] { Parse(ReadPoints3DBinary, points, "p.bin", &out); }),
                  "p.bin: point #1 (id 0) track_length = 18446744073709551615",
                  "count disagrees with file size");
}

TEST(ColmapModelBadInput, UnknownCameraModelId) {
  std::string bytes = Serialize(WriteCamerasBinary, MakeReconstruction());
  for (const int32_t bad : {99, -1, 12}) {
    PatchLE(&bytes, 12, bad);
    Reconstruction out;
    EXPECT_CONTAINS(MessageOf([&] { Parse(ReadCamerasBinary, bytes, "cameras.bin", &out); }),
                    "cameras.bin: camera #1 (id 1) model_id", std::to_string(bad).c_str(),
                    "unknown camera model id", "COLMAP model ids are 0-11");
  }
}

// images.bin with one image whose name field holds `name` (then, if `terminated`, a NUL and an
// empty point list).
std::string ImagesBinWithName(const std::string& name, bool terminated) {
  std::string bytes = U64(1) + std::string(4, '\x05') + std::string(7 * 8 + 4, '\0') + name;
  if (terminated) bytes += std::string(1, '\0') + U64(0);
  return bytes;
}

TEST(ColmapModelBadInput, BadImageNames) {
  Reconstruction out;
  const auto message = [&](const std::string& name, bool terminated) {
    return MessageOf(
        [&] { Parse(ReadImagesBinary, ImagesBinWithName(name, terminated), "images.bin", &out); });
  };
  EXPECT_CONTAINS(message(std::string(100, 'a'), false), "images.bin: image #1 (id 84215045) name",
                  "no terminating NUL");
  EXPECT_CONTAINS(message(std::string(5000, 'a'), true), "images.bin: image #1", "name",
                  "longer than 4096 bytes");
  EXPECT_CONTAINS(message("bad\nname.jpg", true), "name = bad\\x0aname.jpg", "control character");
  EXPECT_CONTAINS(message("", true), "empty image name");
  EXPECT_NO_THROW(
      Parse(ReadImagesBinary, ImagesBinWithName(std::string(4096, 'a'), true), "images.bin", &out));
}

TEST(ColmapModelBadInput, DuplicateIds) {
  Reconstruction rec = MakeReconstruction();
  std::string bytes = Serialize(WriteCamerasBinary, rec);
  const size_t second = 8 + 24 + 8 * 8;  // after camera #1 (OPENCV, 8 params)
  PatchLE(&bytes, second, uint32_t{1});
  Reconstruction out;
  EXPECT_CONTAINS(MessageOf([&] { Parse(ReadCamerasBinary, bytes, "cameras.bin", &out); }),
                  "cameras.bin: camera #2 (id 1) camera_id = 1", "duplicate camera id");
  EXPECT_CONTAINS(MessageOf([&] {
                    Parse(ReadImagesText, "1 1 0 0 0 0 0 0 1 a\n\n1 1 0 0 0 0 0 0 1 b\n\n",
                          "images.txt", &out);
                  }),
                  "images.txt:3", "IMAGE_ID = 1", "duplicate image id");
  EXPECT_CONTAINS(MessageOf([&] {
                    Parse(ReadPoints3DText, "5 0 0 0 1 2 3 0\n5 0 0 0 1 2 3 0\n", "p.txt", &out);
                  }),
                  "p.txt:2", "POINT3D_ID = 5", "duplicate point3D id");
}

TEST(ColmapModelBadInput, TrailingGarbage) {
  const Reconstruction rec = MakeReconstruction();
  for (const BinaryFile& file : kBinaryFiles) {
    Reconstruction out;
    EXPECT_CONTAINS(
        MessageOf([&] { Parse(file.read, Serialize(file.write, rec) + "junk", file.name, &out); }),
        file.name, "4 unexpected bytes after the last record");
  }
}

// ---------------------------------------------------------------------------------------------
// Models that read but do not hang together.

std::string ValidationMessage(const Reconstruction& rec) {
  return MessageOf([&] { ValidateReconstruction(rec, "scene/sparse/0"); });
}

TEST(ColmapModelBadInput, ImageWithMissingCamera) {
  Reconstruction rec = MakeReconstruction();
  rec.images.at(7).camera_id = 99;
  EXPECT_CONTAINS(ValidationMessage(rec), "scene/sparse/0",
                  "image \"sub dir/img 7.png\" (id 7) camera_id = 99", "no camera with this id");
}

TEST(ColmapModelBadInput, TwoImagesWithOneNameInEitherFormat) {
  Reconstruction rec = MakeReconstruction();
  const uint32_t first = rec.images.begin()->first;
  const uint32_t second = std::next(rec.images.begin())->first;
  rec.images.at(second).name = rec.images.at(first).name;  // one photo, two poses
  EXPECT_CONTAINS(ValidationMessage(rec), "scene/sparse/0", "name", "has the same name");
  for (const ModelFormat format : {ModelFormat::kBinary, ModelFormat::kText}) {
    TempDir tmp;
    WriteReconstruction(tmp.path(), rec, format);
    EXPECT_CONTAINS(MessageOf([&] { ReadReconstruction(tmp.path()); }), "same name");
  }
}

TEST(ColmapModelBadInput, TrackWithMissingImageOrPoint) {
  Reconstruction rec = MakeReconstruction();
  rec.points3D.at(1).track[1].image_id = 1234;
  EXPECT_CONTAINS(ValidationMessage(rec), "scene/sparse/0", "point3D 1 track[1] image_id = 1234",
                  "no image with this id");
  rec = MakeReconstruction();
  rec.points3D.at(1).track[0].point2D_idx = 5;  // image 1 has 5 points2D
  EXPECT_CONTAINS(ValidationMessage(rec), "point3D 1 track[0] point2D_idx = 5", "out of range",
                  "has 5 points2D");
}

TEST(ColmapModelBadInput, NonFiniteValues) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  Reconstruction rec = MakeReconstruction();
  rec.images.at(1).qvec[2] = nan;
  EXPECT_CONTAINS(ValidationMessage(rec), "image \"DSC_0001.JPG\" (id 1) pose", "nan",
                  "not finite");
  rec = MakeReconstruction();
  rec.images.at(42).tvec[0] = -inf;
  EXPECT_CONTAINS(ValidationMessage(rec), "(id 42) pose", "-inf", "not finite");
  rec = MakeReconstruction();
  rec.points3D.at(0).xyz[1] = nan;
  EXPECT_CONTAINS(ValidationMessage(rec), "point3D 0 xyz", "not finite");
  rec = MakeReconstruction();
  rec.cameras.at(13).params[0] = inf;
  EXPECT_CONTAINS(ValidationMessage(rec), "camera 13 params", "inf", "not finite");
}

TEST(ColmapModelBadInput, NonUnitQuaternion) {
  Reconstruction rec = MakeReconstruction();
  rec.images.at(1).qvec = {1, 0.1, 0, 0};
  EXPECT_CONTAINS(ValidationMessage(rec), "scene/sparse/0",
                  "image \"DSC_0001.JPG\" (id 1) qvec = 1 0.1 0 0", "not a unit quaternion",
                  "re-export the model from COLMAP");
  rec.images.at(1).qvec = {1.0009, 0, 0, 0};  // within tolerance
  EXPECT_NO_THROW(ValidateReconstruction(rec, "x"));
}

TEST(ColmapModelBadInput, CameraProblems) {
  Reconstruction rec = MakeReconstruction();
  rec.cameras.at(1).params.pop_back();
  EXPECT_CONTAINS(ValidationMessage(rec), "camera 1 params = 7 values",
                  "wrong number of parameters", "OPENCV takes 8");
  rec = MakeReconstruction();
  rec.cameras.at(4).width = 0;
  EXPECT_CONTAINS(ValidationMessage(rec), "camera 4 width = 0", "zero");
  rec = MakeReconstruction();
  rec.cameras.at(4).model_id = 99;
  EXPECT_CONTAINS(ValidationMessage(rec), "camera 4 model_id = 99", "0-11");
}

TEST(ColmapModelBadInput, EmptyModel) {
  Reconstruction rec = MakeReconstruction();
  rec.images.clear();
  rec.points3D.clear();
  EXPECT_CONTAINS(ValidationMessage(rec), "scene/sparse/0", "empty model", "--colmap");
  TempDir tmp;
  WriteReconstruction(tmp.path(), Reconstruction{}, ModelFormat::kBinary);
  EXPECT_CONTAINS(MessageOf([&] { ReadReconstruction(tmp.path()); }), tmp.path().string().c_str(),
                  "empty model");
}

TEST(ColmapModelBadInput, InconsistentFolderNamesFolder) {
  Reconstruction rec = MakeReconstruction();
  rec.images.at(1).camera_id = 2;
  TempDir tmp;
  WriteReconstruction(tmp.path(), rec, ModelFormat::kText);
  EXPECT_CONTAINS(MessageOf([&] { ReadReconstruction(tmp.path()); }), tmp.path().string().c_str(),
                  "camera_id = 2");
}

// ---------------------------------------------------------------------------------------------
// Bad text input: every message gives file:line, the field and the token.

std::string TextMessage(Reader read, const std::string& text) {
  Reconstruction out;
  return MessageOf([&] { Parse(read, text, "model/file.txt", &out); });
}

TEST(ColmapModelBadInput, GarbledCameraLines) {
  const std::string header = "# Camera list\n# more\n";
  EXPECT_CONTAINS(TextMessage(ReadCamerasText, header + "1 OPENCV 800 abc 1 2 3 4 5 6 7 8\n"),
                  "model/file.txt:3: camera 1 HEIGHT = abc: not a non-negative integer");
  EXPECT_CONTAINS(TextMessage(ReadCamerasText, header + "\n1 OPENCV 800\n"), "model/file.txt:4",
                  "camera 1 HEIGHT", "missing");
  EXPECT_CONTAINS(TextMessage(ReadCamerasText, "1 PINHOLE 8 6 1 2 3 x4\n"), "file.txt:1",
                  "PARAMS[3] = x4", "not a number");
  EXPECT_CONTAINS(TextMessage(ReadCamerasText, "1 PINHOLE 8 6 1 2 3\n"), "file.txt:1",
                  "camera 1 PARAMS = 3 values", "PINHOLE takes 4");
  EXPECT_CONTAINS(TextMessage(ReadCamerasText, "1 FISHEYE 8 6 1 2 3\n"), "file.txt:1",
                  "MODEL = FISHEYE", "unknown camera model", "OPENCV_FISHEYE");
  EXPECT_CONTAINS(TextMessage(ReadCamerasText, "-1 PINHOLE 8 6 1 2 3 4\n"), "CAMERA_ID = -1");
  EXPECT_CONTAINS(TextMessage(ReadCamerasText, "4294967296 PINHOLE 8 6 1 2 3 4\n"),
                  "CAMERA_ID = 4294967296", "out of range");
}

TEST(ColmapModelBadInput, GarbledImageLines) {
  EXPECT_CONTAINS(TextMessage(ReadImagesText, "# h\n3 1 0,5 0 0 0 0 0 1 a.jpg\n\n"),
                  "model/file.txt:2: image 3 QX = 0,5: not a number");
  EXPECT_CONTAINS(TextMessage(ReadImagesText, "3 1 0 0 0 0 0 0 1\n\n"), "file.txt:1",
                  "image 3 NAME", "missing");
  EXPECT_CONTAINS(TextMessage(ReadImagesText, "3 1 0 0 0\n"), "file.txt:1", "image 3 TX",
                  "missing");
  EXPECT_CONTAINS(TextMessage(ReadImagesText, "3 1 0 0 0 0 0 0 1 a.jpg\n1 2 -1 4 5\n"),
                  "file.txt:2", "image 3 POINTS2D[1] POINT3D_ID", "missing");
  EXPECT_CONTAINS(TextMessage(ReadImagesText, "3 1 0 0 0 0 0 0 1 a.jpg\n1 2 -2\n"), "file.txt:2",
                  "POINTS2D[0] POINT3D_ID = -2");
  EXPECT_CONTAINS(TextMessage(ReadImagesText, "3 1 0 0 0 0 0 0 1 a\x01.jpg\n\n"),
                  "NAME = a\\x01.jpg", "control character");
}

TEST(ColmapModelBadInput, GarbledPointLines) {
  EXPECT_CONTAINS(TextMessage(ReadPoints3DText, "7 1 2 3 10 20 30 0.5 1 0 2\n"), "model/file.txt:1",
                  "point 7 TRACK[1] POINT2D_IDX", "missing");
  EXPECT_CONTAINS(TextMessage(ReadPoints3DText, "7 1 2 3 10 300 30 0.5\n"), "point 7 G = 300",
                  "0-255");
  EXPECT_CONTAINS(TextMessage(ReadPoints3DText, "7 1 2 z 10 20 30 0.5\n"), "point 7 Z = z",
                  "not a number");
  EXPECT_CONTAINS(TextMessage(ReadPoints3DText, "7 1 2 3 10 20 30\n"), "point 7 ERROR", "missing");
}

// ---------------------------------------------------------------------------------------------
// Folders.

TEST(ColmapModelBadInput, MissingFolderOrFiles) {
  TempDir tmp;
  const fs::path none = tmp.path() / "no_such_folder";
  EXPECT_CONTAINS(MessageOf([&] { DetectModelFormat(none); }), none.string().c_str(),
                  "folder does not exist", "sparse/0");
  EXPECT_CONTAINS(MessageOf([&] { ReadReconstruction(none); }), "folder does not exist");

  std::ofstream(tmp.path() / "cameras.bin") << "x";
  EXPECT_CONTAINS(MessageOf([&] { DetectModelFormat(tmp.path() / "cameras.bin"); }),
                  "not a folder");
  const std::string msg = MessageOf([&] { DetectModelFormat(tmp.path()); });
  EXPECT_CONTAINS(msg, tmp.path().string().c_str(),
                  "missing images.bin, points3D.bin (binary model)",
                  "cameras.txt, images.txt, points3D.txt (text model)", "--colmap", "sparse/0");

  // Pointing at the project instead of the model inside it: the hint names the model folder.
  WriteReconstruction(tmp.path() / "sparse" / "0", MakeReconstruction(), ModelFormat::kBinary);
  EXPECT_CONTAINS(MessageOf([&] { DetectModelFormat(tmp.path()); }),
                  (tmp.path() / "sparse/0").string().c_str(), "holds a model");
}

}  // namespace
}  // namespace perf::colmap
