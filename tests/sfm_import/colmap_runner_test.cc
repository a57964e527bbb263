// RunSfm against the real `colmap` binary on photos this test renders itself (a textured box
// scene seen from an arc of cameras, so the true poses are known), plus its error paths and
// model selection driven by a fake colmap script (no colmap needed for those).
#include "sfm_import/colmap_runner.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "common/errors.h"
#include "sfm_import/camera_groups.h"
#include "sfm_import/capture_order.h"
#include "sfm_import/colmap_model.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

// ---------------------------------------------------------------------------------------------
// Helpers

bool ColmapOnPath() {
  const char* path = std::getenv("PATH");
  std::string list = path ? path : "";
  size_t begin = 0;
  while (begin <= list.size()) {
    size_t end = list.find(':', begin);
    if (end == std::string::npos) end = list.size();
    const fs::path candidate = fs::path(list.substr(begin, end - begin)) / "colmap";
    if (end > begin && ::access(candidate.c_str(), X_OK) == 0) return true;
    begin = end + 1;
  }
  return false;
}

// A fresh folder per test, removed afterwards. The space in the name checks that no step goes
// through a shell.
class TempDir {
 public:
  explicit TempDir(const std::string& name) {
    path_ = fs::temp_directory_path() /
            ("perf colmap_runner " + name + " " + std::to_string(::getpid()));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    if (!std::getenv("PERF_KEEP_TEST_DIRS")) fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

void WriteFile(const fs::path& path, const std::string& contents) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << contents;
  ASSERT_TRUE(out.good()) << path;
}

// A small JPEG (or PNG) with the given EXIF camera tags (none when make is empty) and capture
// time (none when empty).
void WriteTaggedPhoto(const fs::path& path, int w, int h, const std::string& make, float focal_mm,
                      const std::string& time = {}) {
  fs::create_directories(path.parent_path());
  OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
  if (!make.empty()) {
    spec.attribute("Make", make);
    spec.attribute("Model", "Model 1");
    spec.attribute("Exif:FocalLength", focal_mm);
  }
  if (!time.empty()) spec.attribute("Exif:DateTimeOriginal", time);
  std::vector<unsigned char> pixels(static_cast<size_t>(w) * h * 3, 128);
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out && out->open(path.string(), spec)) << path;
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  out->close();
}

// A plain photo (no EXIF) that the up-front header check reads; COLMAP stand-ins never look at it.
void WritePhoto(const fs::path& path) { WriteTaggedPhoto(path, 16, 12, "", 0.f); }

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::string LittleEndianCount(uint64_t n) {
  std::string s(8, '\0');
  for (int i = 0; i < 8; ++i) s[i] = static_cast<char>((n >> (8 * i)) & 0xff);
  return s;
}

// A binary model that only has the headers RunSfm reads (counts); enough for selection logic.
void WriteFakeModel(const fs::path& dir, uint64_t num_images, uint64_t num_points) {
  WriteFile(dir / "cameras.bin", LittleEndianCount(1));
  WriteFile(dir / "images.bin", LittleEndianCount(num_images));
  WriteFile(dir / "points3D.bin", LittleEndianCount(num_points));
}

// Whether a progress line contains `text`.
bool Said(const std::vector<std::string>& progress, const std::string& text) {
  return std::any_of(progress.begin(), progress.end(), [&](const std::string& l) { return l.find(text) != std::string::npos; });
}

void WriteExecutable(const fs::path& path, const std::string& script) {
  WriteFile(path, script);
  fs::permissions(path, fs::perms::owner_all, fs::perm_options::add);
}

// ---------------------------------------------------------------------------------------------
// Synthetic photos: ground plane and two boxes with a multi-scale noise texture (blobs and
// sharp-edged squares at several sizes, so SIFT finds many stable features), Lambertian shading
// with a fixed light so every view sees the same surface colours.

constexpr int kWidth = 320, kHeight = 240;
constexpr double kFocal = 384;  // = 1.2 * max(w, h), COLMAP's prior when there is no EXIF

uint32_t Hash(int32_t a, int32_t b, int32_t c) {
  uint32_t h = static_cast<uint32_t>(a) * 0x8da6b343u ^ static_cast<uint32_t>(b) * 0xd8163841u ^
               static_cast<uint32_t>(c) * 0xcb1ab31fu;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  h ^= h >> 15;
  return h;
}

double HashUnit(int32_t a, int32_t b, int32_t c) { return (Hash(a, b, c) & 0xffffff) / 16777216.0; }

double ValueNoise(double s, double t, double cell, int seed) {
  const double x = s / cell, y = t / cell;
  const int i = static_cast<int>(std::floor(x)), j = static_cast<int>(std::floor(y));
  const double fx = x - i, fy = y - j;
  auto v = [&](int di, int dj) { return HashUnit(i + di, j + dj, seed); };
  return (v(0, 0) * (1 - fx) + v(1, 0) * fx) * (1 - fy) + (v(0, 1) * (1 - fx) + v(1, 1) * fx) * fy;
}

double BlockNoise(double s, double t, double cell, int seed) {
  return HashUnit(static_cast<int>(std::floor(s / cell)), static_cast<int>(std::floor(t / cell)),
                  seed);
}

// Texture value in [0, 1] at surface coordinates (s, t) of surface `id`.
double Texture(double s, double t, int id) {
  return 0.3 * ValueNoise(s, t, 0.07, 10 * id + 1) + 0.3 * ValueNoise(s, t, 0.2, 10 * id + 2) +
         0.4 * BlockNoise(s, t, 0.11, 10 * id + 3);
}

struct Hit {
  double t = std::numeric_limits<double>::infinity();
  Eigen::Vector3d normal;
  double s = 0, u = 0;  // surface coordinates
  int id = -1;
};

void IntersectBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& lo,
                  const Eigen::Vector3d& hi, int id, Hit* hit) {
  double tmin = 0, tmax = std::numeric_limits<double>::infinity();
  int axis = -1;
  double sign = 0;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (o[a] < lo[a] || o[a] > hi[a]) return;
      continue;
    }
    double t0 = (lo[a] - o[a]) / d[a], t1 = (hi[a] - o[a]) / d[a];
    double s = -1;
    if (t0 > t1) {
      std::swap(t0, t1);
      s = 1;
    }
    if (t0 > tmin) {
      tmin = t0;
      axis = a;
      sign = s;
    }
    tmax = std::min(tmax, t1);
    if (tmin > tmax) return;
  }
  if (axis < 0 || tmin >= hit->t) return;  // camera inside or farther than the current hit
  const Eigen::Vector3d p = o + tmin * d;
  hit->t = tmin;
  hit->normal = Eigen::Vector3d::Zero();
  hit->normal[axis] = sign;
  hit->s = p[(axis + 1) % 3];
  hit->u = p[(axis + 2) % 3];
  hit->id = id * 6 + axis * 2 + (sign > 0);
}

Eigen::Vector3d Shade(const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  Hit hit;
  if (d.z() < 0) {  // ground plane z = 0, 8 x 8 units
    const double t = -o.z() / d.z();
    const Eigen::Vector3d p = o + t * d;
    if (std::abs(p.x()) < 4 && std::abs(p.y()) < 4) {
      hit.t = t;
      hit.normal = Eigen::Vector3d::UnitZ();
      hit.s = p.x();
      hit.u = p.y();
      hit.id = 100;
    }
  }
  IntersectBox(o, d, {-0.6, -0.6, 0}, {0.6, 0.6, 1.2}, 1, &hit);
  IntersectBox(o, d, {0.9, -1.5, 0}, {1.6, -0.8, 0.7}, 2, &hit);
  IntersectBox(o, d, {-1.8, -0.2, 0}, {-1.2, 0.6, 0.9}, 3, &hit);
  if (hit.id < 0) return {0.65, 0.75, 0.9};  // featureless sky
  const Eigen::Vector3d light = Eigen::Vector3d(0.4, -0.5, 0.75).normalized();
  const double shade = 0.35 + 0.65 * std::max(0.0, hit.normal.dot(light));
  const double tex = Texture(hit.s, hit.u, hit.id);
  const Eigen::Vector3d tint(0.7 + 0.3 * HashUnit(hit.id, 0, 7), 0.7 + 0.3 * HashUnit(hit.id, 1, 7),
                             0.7 + 0.3 * HashUnit(hit.id, 2, 7));
  return (0.1 + 0.9 * tex) * shade * tint;
}

struct TrueCamera {
  std::string name;
  Eigen::Matrix3d cam_from_world;  // rows: camera x (right), y (down), z (forward) in world
  Eigen::Vector3d centre;
};

// Cameras on an arc around the scene, looking at its middle; world z is up.
std::vector<TrueCamera> ArcCameras(int count) {
  std::vector<TrueCamera> cams;
  const Eigen::Vector3d target(0, -0.2, 0.4);
  for (int i = 0; i < count; ++i) {
    const double angle = (-50.0 + 100.0 * i / (count - 1)) * M_PI / 180;
    TrueCamera cam;
    cam.name = "view " + std::to_string(100 + i) + ".png";
    // Alternating distance and height: at one distance, focal length and depth trade off and
    // self-calibration is poorly conditioned.
    const double radius = i % 2 ? 5.2 : 4.2, height = i % 3 == 0 ? 3.2 : 2.2;
    cam.centre = Eigen::Vector3d(radius * std::sin(angle), -radius * std::cos(angle), height);
    const Eigen::Vector3d forward = (target - cam.centre).normalized();
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    const Eigen::Vector3d down = forward.cross(right);
    cam.cam_from_world.row(0) = right;
    cam.cam_from_world.row(1) = down;
    cam.cam_from_world.row(2) = forward;
    cams.push_back(cam);
  }
  return cams;
}

void RenderView(const TrueCamera& cam, const fs::path& path) {
  constexpr int kSamples = 3;  // per axis: anti-aliasing keeps the fine texture stable across views
  std::vector<uint8_t> pixels(static_cast<size_t>(kWidth) * kHeight * 3);
  const Eigen::Matrix3d world_from_cam = cam.cam_from_world.transpose();
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int sy = 0; sy < kSamples; ++sy) {
        for (int sx = 0; sx < kSamples; ++sx) {
          // COLMAP convention: the upper-left pixel's centre is (0.5, 0.5).
          const double px = x + (sx + 0.5) / kSamples, py = y + (sy + 0.5) / kSamples;
          const Eigen::Vector3d dir =
              world_from_cam *
              Eigen::Vector3d((px - kWidth / 2.0) / kFocal, (py - kHeight / 2.0) / kFocal, 1);
          sum += Shade(cam.centre, dir.normalized());
        }
      }
      sum /= kSamples * kSamples;
      for (int c = 0; c < 3; ++c) {
        pixels[(static_cast<size_t>(y) * kWidth + x) * 3 + c] =
            static_cast<uint8_t>(std::clamp(sum[c], 0.0, 1.0) * 255 + 0.5);
      }
    }
  }
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out) << OIIO::geterror();
  OIIO::ImageSpec spec(kWidth, kHeight, 3, OIIO::TypeDesc::UINT8);
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data())) << out->geterror();
  ASSERT_TRUE(out->close());
}

// ---------------------------------------------------------------------------------------------
// Minimal readers for what the test checks in COLMAP's binary model (kept here so this test
// does not depend on the full model reader).

template <typename T>
T Read(std::istream& in) {
  T v{};
  in.read(reinterpret_cast<char*>(&v), sizeof v);
  return v;
}

std::map<std::string, Eigen::Vector3d> ReadCentres(const fs::path& images_bin) {
  std::ifstream in(images_bin, std::ios::binary);
  std::map<std::string, Eigen::Vector3d> centres;
  const auto n = Read<uint64_t>(in);
  for (uint64_t i = 0; i < n && in; ++i) {
    Read<uint32_t>(in);  // image_id
    double q[4], t[3];
    for (double& v : q) v = Read<double>(in);
    for (double& v : t) v = Read<double>(in);
    Read<uint32_t>(in);  // camera_id
    std::string name;
    std::getline(in, name, '\0');
    const auto num_points2D = Read<uint64_t>(in);
    in.seekg(static_cast<std::streamoff>(num_points2D * 24), std::ios::cur);
    const Eigen::Matrix3d r = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).toRotationMatrix();
    centres[name] = -r.transpose() * Eigen::Vector3d(t[0], t[1], t[2]);
  }
  EXPECT_TRUE(in.good()) << images_bin;
  return centres;
}

// (model id, first parameter = fx or f) of the first camera.
std::pair<int, double> ReadFirstCamera(const fs::path& cameras_bin) {
  std::ifstream in(cameras_bin, std::ios::binary);
  Read<uint64_t>(in);  // count
  Read<uint32_t>(in);  // camera_id
  const auto model = Read<int32_t>(in);
  Read<uint64_t>(in);  // width
  Read<uint64_t>(in);  // height
  return {model, Read<double>(in)};
}

// ---------------------------------------------------------------------------------------------
// The real thing

TEST(ColmapRunner, ReconstructsSyntheticArc) {
  if (!ColmapOnPath()) {
    GTEST_SKIP() << "`colmap` is not on PATH; install it (apt-get install colmap or "
                    "scripts/setup.sh) to run this test";
  }
  TempDir dir("arc");
  const fs::path images = dir.path() / "photos";
  fs::create_directories(images);
  const std::vector<TrueCamera> cams = ArcCameras(12);
  for (const auto& cam : cams) RenderView(cam, images / cam.name);

  SfmOptions options;
  options.images = images;
  options.workspace = dir.path() / "work space";
  options.matcher = "exhaustive";
  options.num_threads = 2;
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };

  // COLMAP's glog writes files where TMPDIR says unless told otherwise: none may land outside
  // the workspace.
  const fs::path tmp = dir.path() / "tmp";
  fs::create_directories(tmp);
  const char* old_tmp = std::getenv("TMPDIR");
  const std::string kept_tmp = old_tmp != nullptr ? old_tmp : "";
  ::setenv("TMPDIR", tmp.c_str(), 1);
  const auto start = std::chrono::steady_clock::now();
  const SfmResult result = RunSfm(options);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  old_tmp != nullptr ? ::setenv("TMPDIR", kept_tmp.c_str(), 1) : ::unsetenv("TMPDIR");
  EXPECT_TRUE(fs::is_empty(tmp)) << "COLMAP wrote files outside the workspace, e.g. " << fs::directory_iterator(tmp)->path();
  EXPECT_FALSE(fs::exists(options.workspace / "colmap" / "glog" / "colmap.INFO"));
  std::cout << "synthetic sfm (12 images, " << kWidth << "x" << kHeight
            << ", exhaustive): " << seconds << " s\n";
  for (const auto& line : progress) std::cout << "  progress: " << line << "\n";

  EXPECT_EQ(result.num_input_images, 12);
  EXPECT_GE(result.num_registered_images, 9);
  EXPECT_GT(result.num_points, 200);
  EXPECT_GT(result.seconds, 0);
  EXPECT_EQ(result.sparse_dir, options.workspace / "sparse" / "0");
  for (const char* file : {"cameras.bin", "images.bin", "points3D.bin"}) {
    EXPECT_TRUE(fs::is_regular_file(result.sparse_dir / file)) << file;
  }
  const fs::path log = options.workspace / "colmap" / "colmap.log";
  ASSERT_TRUE(fs::is_regular_file(log));
  const std::string log_text = ReadFile(log);
  EXPECT_NE(log_text.find("feature_extractor"), std::string::npos);
  EXPECT_NE(log_text.find("exhaustive_matcher"), std::string::npos);
  EXPECT_NE(log_text.find("mapper"), std::string::npos);
  auto has_progress = [&](const std::string& needle) {
    return std::any_of(progress.begin(), progress.end(),
                       [&](const std::string& l) { return l.find(needle) != std::string::npos; });
  };
  EXPECT_TRUE(has_progress("extracting features"));
  EXPECT_TRUE(has_progress("exhaustive"));
  EXPECT_TRUE(has_progress("images registered"));

  // Intrinsics: the default model, with the focal length the views were rendered with.
  const auto [model_id, focal] = ReadFirstCamera(result.sparse_dir / "cameras.bin");
  EXPECT_EQ(model_id, 2);  // SIMPLE_RADIAL
  std::cout << "recovered focal length: " << focal << " px (rendered with " << kFocal << ")\n";
  EXPECT_NEAR(focal, kFocal, 0.03 * kFocal);

  // Poses: the recovered camera centres equal the true ones up to a similarity (COLMAP's frame
  // and scale are arbitrary).
  const auto centres = ReadCentres(result.sparse_dir / "images.bin");
  ASSERT_EQ(static_cast<int>(centres.size()), result.num_registered_images);
  Eigen::Matrix3Xd recovered(3, centres.size()), truth(3, centres.size());
  int k = 0;
  for (const auto& [name, centre] : centres) {
    const auto it =
        std::find_if(cams.begin(), cams.end(), [&](const TrueCamera& c) { return c.name == name; });
    ASSERT_NE(it, cams.end()) << name;
    recovered.col(k) = centre;
    truth.col(k) = it->centre;
    ++k;
  }
  const Eigen::Matrix4d truth_from_recovered = Eigen::umeyama(recovered, truth, true);
  const Eigen::Matrix3Xd aligned =
      (truth_from_recovered.topLeftCorner<3, 3>() * recovered).colwise() +
      truth_from_recovered.topRightCorner<3, 1>();
  const double max_error = (aligned - truth).colwise().norm().maxCoeff();
  const double extent = (cams.front().centre - cams.back().centre).norm();  // ~6.9 units
  std::cout << "max camera centre error after similarity alignment: " << max_error << " ("
            << 100 * max_error / extent << "% of the arc)\n";
  EXPECT_LT(max_error, 0.02 * extent);  // observed 0.2-0.5% over repeated runs

  // A second run finds the model and does not run COLMAP again.
  progress.clear();
  const SfmResult again = RunSfm(options);
  EXPECT_EQ(again.num_registered_images, result.num_registered_images);
  EXPECT_EQ(again.num_points, result.num_points);
  EXPECT_TRUE(has_progress("skipped"));
  EXPECT_LT(again.seconds, 1.0);
}

TEST(ColmapRunner, UnrelatedPhotosAreAnInputError) {
  if (!ColmapOnPath()) GTEST_SKIP() << "`colmap` is not on PATH";
  TempDir dir("unrelated");
  const fs::path images = dir.path() / "photos";
  fs::create_directories(images);
  // Pure noise: plenty of features, but no two photos show the same thing.
  for (int i = 0; i < 3; ++i) {
    std::vector<uint8_t> pixels(kWidth * kHeight);
    for (size_t p = 0; p < pixels.size(); ++p) {
      pixels[p] = static_cast<uint8_t>(Hash(static_cast<int>(p / 4), i, 99) & 0xff);
    }
    const std::string path = (images / ("noise" + std::to_string(i) + ".png")).string();
    auto out = OIIO::ImageOutput::create(path);
    ASSERT_TRUE(out);
    ASSERT_TRUE(out->open(path, OIIO::ImageSpec(kWidth, kHeight, 1, OIIO::TypeDesc::UINT8)));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
    out->close();
  }
  SfmOptions options;
  options.images = images;
  options.workspace = dir.path() / "work";
  options.num_threads = 2;
  // Each step prints within seconds here; a hang (seen once in a suite run) fails in 2 minutes
  // with the tail of COLMAP's log instead of at CTest's timeout.
  options.idle_timeout_seconds = 120;
  try {
    RunSfm(options);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "registered images");
    EXPECT_NE(std::string(e.what()).find("overlap"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Errors and workspace handling (no colmap needed)

TEST(ColmapRunner, MissingImagesFolder) {
  TempDir dir("missing");
  SfmOptions options;
  options.images = dir.path() / "no such folder";
  options.workspace = dir.path() / "work";
  try {
    RunSfm(options);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "--images");
    EXPECT_EQ(e.value(), options.images.string());
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
}

TEST(ColmapRunner, EmptyImagesFolder) {
  TempDir dir("empty");
  SfmOptions options;
  options.images = dir.path() / "photos";
  fs::create_directories(options.images);
  WriteFile(options.images / "notes.txt", "not a photo");
  options.workspace = dir.path() / "work";
  try {
    RunSfm(options);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "--images");
    EXPECT_NE(std::string(e.what()).find(options.images.string()), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("no images"), std::string::npos) << e.what();
  }
}

TEST(ColmapRunner, ColmapNotFound) {
  TempDir dir("nocolmap");
  SfmOptions options;
  options.images = dir.path() / "photos";
  WritePhoto(options.images / "a.jpg");
  options.workspace = dir.path() / "work";

  options.colmap_binary = "/nonexistent/colmap";
  try {
    RunSfm(options);
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_EQ(e.path(), "/nonexistent/colmap");
    EXPECT_NE(std::string(e.what()).find("apt-get install colmap"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--colmap-binary"), std::string::npos) << e.what();
  }

  options.colmap_binary = "perf-no-such-colmap";
  try {
    RunSfm(options);
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("not found on PATH"), std::string::npos) << e.what();
  }
}

TEST(ColmapRunner, CheckNamesTheBadOption) {
  SfmOptions options;
  options.images = "photos";
  options.workspace = "work";
  EXPECT_NO_THROW(options.Check());

  auto field_of = [](const SfmOptions& o) -> std::string {
    try {
      o.Check();
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "command line");
      return e.field();
    }
    return "";
  };
  SfmOptions o = options;
  o.matcher = "vocab_tree";
  EXPECT_EQ(field_of(o), "--matcher");
  o = options;
  o.camera_model = "opencv";
  EXPECT_EQ(field_of(o), "--camera-model");
  o = options;
  o.camera_model = "FOV";  // COLMAP's, but perf import could not undistort what it gives
  EXPECT_EQ(field_of(o), "--camera-model");
  o = options;
  o.camera_model = "SIMPLE_RADIAL";
  EXPECT_EQ(field_of(o), "");
  o = options;
  o.max_image_size = 0;
  EXPECT_EQ(field_of(o), "--max-image-size");
  o = options;
  o.max_num_features = -5;
  EXPECT_EQ(field_of(o), "--max-features");  // the names perf sfm --help lists
  o = options;
  o.sequential_overlap = 0;
  EXPECT_EQ(field_of(o), "--overlap");
  o = options;
  o.min_pose_inliers = -1;
  EXPECT_EQ(field_of(o), "--min-pose-inliers");
  for (double ratio : {0.0, 1.0, std::nan("")}) {
    o = options;
    o.min_pose_inlier_ratio = ratio;
    EXPECT_EQ(field_of(o), "--min-pose-inlier-ratio") << ratio;
  }
  o = options;
  o.max_num_features = 1024;
  EXPECT_EQ(o.MinPoseInliers(), 30);  // COLMAP's own where the features are few
  o.min_pose_inliers = 55;
  EXPECT_EQ(o.MinPoseInliers(), 55);
  o = options;
  o.num_threads = 0;
  EXPECT_EQ(field_of(o), "-j");
  o = options;
  o.min_registered_images = 1;
  EXPECT_EQ(field_of(o), "--min-registered");
  o = options;
  o.images.clear();
  EXPECT_EQ(field_of(o), "--images");
}

TEST(ColmapRunner, SkipsWhenModelExists) {
  TempDir dir("skip");
  SfmOptions options;
  options.images = dir.path() / "photos";
  WritePhoto(options.images / "a.jpg");
  WritePhoto(options.images / "sub" / "b.PNG");
  options.workspace = dir.path() / "work";
  WriteFakeModel(options.workspace / "sparse" / "0", 5, 123);
  options.colmap_binary = "/nonexistent/colmap";  // proves that colmap is not run
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };

  const SfmResult result = RunSfm(options);
  EXPECT_EQ(result.num_input_images, 2);
  EXPECT_EQ(result.num_registered_images, 5);
  EXPECT_EQ(result.num_points, 123);
  EXPECT_EQ(result.sparse_dir, options.workspace / "sparse" / "0");
  ASSERT_EQ(progress.size(), 1u);
  EXPECT_NE(progress[0].find("skipped"), std::string::npos) << progress[0];

  // --force runs again, so it needs colmap.
  options.force = true;
  EXPECT_THROW(RunSfm(options), IoError);
}

// A stand-in for colmap: echoes its environment and arguments, reports progress like COLMAP
// 3.8 does, and (mapper) writes two models of different sizes.
constexpr const char* kFakeColmap = R"SH(#!/bin/sh
PATH=/usr/bin:/bin:$PATH
step="$1"
echo "fake colmap $step QT_QPA_PLATFORM=$QT_QPA_PLATFORM"
for a in "$@"; do echo "arg=[$a]"; done
case "$step" in
  feature_extractor)
    echo "Processed file [1/3]"; sleep 1.2; echo "Processed file [2/3]" >&2
    echo "Processed file [3/3]" ;;
  mapper)
    while [ $# -gt 0 ]; do [ "$1" = "--output_path" ] && out="$2"; shift; done
    mkdir -p "$out/0" "$out/1" "$out/notes"
    printf '\001\000\000\000\000\000\000\000' > "$out/0/cameras.bin"
    printf '\002\000\000\000\000\000\000\000' > "$out/0/images.bin"
    printf '\100\000\000\000\000\000\000\000' > "$out/0/points3D.bin"
    cp "$out/0/cameras.bin" "$out/1/cameras.bin"
    printf '\003\000\000\000\000\000\000\000' > "$out/1/images.bin"
    printf '\040\000\000\000\000\000\000\000' > "$out/1/points3D.bin"
    echo "Registering image #2 (3)" ;;
esac
exit 0
)SH";

TEST(ColmapRunner, FakeColmapPicksLargestModelAndReplacesOldOne) {
  TempDir dir("fake");
  SfmOptions options;
  options.images = dir.path() / "my photos";
  WritePhoto(options.images / "a.jpg");
  WritePhoto(options.images / "b.jpg");
  options.workspace = dir.path() / "work";
  options.colmap_binary = (dir.path() / "bin" / "colmap").string();
  WriteExecutable(options.colmap_binary, kFakeColmap);
  WriteFakeModel(options.workspace / "sparse" / "0", 7, 7);  // an older model, to be replaced
  WriteFile(options.workspace / "sparse" / "0" / "stale.txt", "old");
  options.force = true;
  options.min_registered_images = 3;
  options.single_camera = false;
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };

  const SfmResult result = RunSfm(options);
  EXPECT_EQ(result.num_registered_images, 3);  // model 1, not model 0 (2 images)
  EXPECT_EQ(result.num_points, 32);
  EXPECT_FALSE(fs::exists(result.sparse_dir / "stale.txt"));
  EXPECT_EQ(ReadFile(result.sparse_dir / "images.bin"), LittleEndianCount(3));
  // No temporary or old folders left beside it.
  int entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(options.workspace / "sparse"))
    ++entries;
  EXPECT_EQ(entries, 1);

  const std::string log = ReadFile(options.workspace / "colmap" / "colmap.log");
  EXPECT_NE(log.find("QT_QPA_PLATFORM=offscreen"), std::string::npos);
  // Arguments reach colmap intact, spaces included.
  EXPECT_NE(log.find("arg=[" + options.images.string() + "]"), std::string::npos) << log;
  EXPECT_NE(log.find("arg=[exhaustive_matcher]"), std::string::npos);  // auto, 2 images
  EXPECT_NE(log.find("arg=[--ImageReader.single_camera]\narg=[0]"), std::string::npos);
  EXPECT_NE(log.find("Processed file [2/3]"), std::string::npos);  // stderr is logged too
  EXPECT_NE(log.find("] exit code 0"), std::string::npos);
  // Progress while a step runs (throttled to one a second; the fake sleeps 1.2 s before 2/3),
  // then the step's last status when it ends.
  auto at = [&](const std::string& line) {
    return std::find(progress.begin(), progress.end(), line);
  };
  ASSERT_NE(at("features: 2/3 images"), progress.end());
  ASSERT_NE(at("features: 3/3 images"), progress.end());
  EXPECT_LT(at("features: 2/3 images"), at("features: 3/3 images"));
  EXPECT_NE(at("mapping: 3/2 images registered"), progress.end());
  EXPECT_NE(std::find_if(progress.begin(), progress.end(),
                         [](const std::string& l) { return l.find("(the largest of 2 models of 3 and 2 photos)") != std::string::npos; }),
            progress.end());

  // Too few images for a stricter minimum.
  options.min_registered_images = 4;
  try {
    RunSfm(options);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "registered images");
    EXPECT_EQ(e.value(), "3 of 2");
    EXPECT_NE(std::string(e.what()).find("too few images registered"), std::string::npos);
  }

  // Sequential matching beyond the exhaustive limit.
  options.min_registered_images = 2;
  options.exhaustive_max_images = 1;
  options.sequential_overlap = 4;
  RunSfm(options);
  const std::string log2 = ReadFile(options.workspace / "colmap" / "colmap.log");
  EXPECT_NE(log2.find("arg=[sequential_matcher]"), std::string::npos);
  EXPECT_NE(log2.find("arg=[--SequentialMatching.overlap]\narg=[4]"), std::string::npos);
}

// Options for one photo in `dir` and a fake colmap there that runs `script`.
SfmOptions WithFakeColmap(const TempDir& dir, const std::string& script) {
  SfmOptions options;
  options.images = dir.path() / "photos";
  WritePhoto(options.images / "a.jpg");
  options.workspace = dir.path() / "work";
  options.colmap_binary = (dir.path() / "colmap").string();
  WriteExecutable(options.colmap_binary, script);
  return options;
}

// A model is kept while it was made from the photos given; other photos (added, gone, or
// another folder) run COLMAP again and say why. A model no run recorded is kept as before.
TEST(ColmapRunner, AModelOfOtherPhotosIsMadeAgain) {
  TempDir dir("inputs");
  SfmOptions options = WithFakeColmap(dir, kFakeColmap);
  WritePhoto(options.images / "b.jpg");
  options.min_registered_images = 2;
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };
  const auto said = [&](const std::string& text) {
    return std::any_of(progress.begin(), progress.end(), [&](const std::string& l) { return l.find(text) != std::string::npos; });
  };
  const auto runs = [&] { return static_cast<int>(ReadFile(options.workspace / "colmap" / "colmap.log").size()); };

  RunSfm(options);
  ASSERT_TRUE(fs::exists(options.workspace / "colmap" / "inputs.json"));
  const int after_first = runs();
  progress.clear();
  RunSfm(options);
  EXPECT_TRUE(said("sfm: skipped")) << progress.front();
  EXPECT_EQ(runs(), after_first) << "colmap ran for the same photos";

  WritePhoto(options.images / "c.jpg");
  progress.clear();
  RunSfm(options);
  EXPECT_TRUE(said("was made from other photos (1 added since: c.jpg): running COLMAP again")) << progress.front();
  EXPECT_GT(runs(), after_first);

  fs::remove(options.images / "a.jpg");
  progress.clear();
  RunSfm(options);
  EXPECT_TRUE(said("was made from other photos (1 gone: a.jpg): running COLMAP again")) << progress.front();

  const fs::path other = dir.path() / "other";
  fs::copy(options.images, other);
  options.images = other;
  progress.clear();
  RunSfm(options);
  EXPECT_TRUE(said("was made from the photos in " + (dir.path() / "photos").string())) << progress.front();

  // Without a record (an older perf's model): kept, whatever the folder holds now.
  fs::remove(options.workspace / "colmap" / "inputs.json");
  WritePhoto(other / "d.jpg");
  progress.clear();
  RunSfm(options);
  EXPECT_TRUE(said("sfm: skipped")) << progress.front();
}

// A model holding the named photos (one camera, no points), as COLMAP writes it.
void WriteNamedModel(const fs::path& dir, const std::vector<std::string>& names) {
  colmap::Reconstruction rec;
  colmap::Camera cam;
  cam.camera_id = 1;
  cam.model_id = 1;  // PINHOLE
  cam.width = 64;
  cam.height = 48;
  cam.params = {60, 60, 32, 24};
  rec.cameras[1] = cam;
  for (size_t i = 0; i < names.size(); ++i) {
    colmap::Image im;
    im.image_id = static_cast<uint32_t>(i + 1);
    im.camera_id = 1;
    im.name = names[i];
    rec.images[im.image_id] = im;
  }
  fs::create_directories(dir);
  colmap::WriteReconstruction(dir, rec, colmap::ModelFormat::kBinary);
}

// Sequential matching leaves c.jpg out: the second pass matches it with every other photo,
// registers it into the model and adjusts; the result holds all three. Without the second pass
// (or when it registers nothing) the photo left out is named, with a warning under 90 %.
TEST(ColmapRunner, SecondPassRegistersThePhotosSequentialMatchingLeftOut) {
  TempDir dir("second");
  const fs::path first = dir.path() / "first", full = dir.path() / "full";
  WriteNamedModel(first, {"a.jpg", "b.jpg"});
  WriteNamedModel(full, {"a.jpg", "b.jpg", "c.jpg"});
  const std::string script = StrCat(R"SH(#!/bin/sh
PATH=/usr/bin:/bin:$PATH
step="$1"
echo "fake colmap $step"
for a in "$@"; do echo "arg=[$a]"; done
while [ $# -gt 0 ]; do
  case "$1" in --output_path) out="$2";; --match_list_path) pairs="$2";; esac; shift
done
case "$step" in
  mapper) mkdir -p "$out/0" && cp ")SH", first.string(), R"SH("/* "$out/0/" ;;
  matches_importer) echo "pairs:"; cat "$pairs" ;;
  image_registrator) cp ")SH", full.string(), R"SH("/* "$out/" ;;
esac
exit 0
)SH");
  SfmOptions options;
  options.images = dir.path() / "photos";
  for (const char* name : {"a.jpg", "b.jpg", "c.jpg"}) WritePhoto(options.images / name);
  options.workspace = dir.path() / "work";
  options.colmap_binary = (dir.path() / "bin" / "colmap").string();
  WriteExecutable(options.colmap_binary, script);
  options.exhaustive_max_images = 1;  // sequential
  options.min_registered_images = 2;
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };
  const auto said = [&](const std::string& text) { return Said(progress, text); };

  SfmResult r = RunSfm(options);
  EXPECT_EQ(r.num_registered_images, 3);
  EXPECT_TRUE(r.left_out.empty());
  EXPECT_TRUE(said("2/3 images registered after sequential matching; matching the 1 left out with every other photo (2 pairs)"));
  const std::string log = ReadFile(options.workspace / "colmap" / "colmap.log");
  EXPECT_NE(log.find("pairs:\nc.jpg a.jpg\nc.jpg b.jpg\n"), std::string::npos) << log;
  EXPECT_NE(log.find("arg=[image_registrator]"), std::string::npos);
  EXPECT_NE(log.find("arg=[bundle_adjuster]"), std::string::npos);
  EXPECT_FALSE(said("warning"));
  // The mapper and the registration place a photo only on 102 inliers (8192 features / 80) and 40 %.
  const std::string strict = "arg=[--Mapper.abs_pose_min_num_inliers]\narg=[102]\narg=[--Mapper.abs_pose_min_inlier_ratio]\narg=[0.4]";
  EXPECT_NE(log.find("arg=[mapper]"), std::string::npos);
  size_t placements = 0;
  for (size_t at = log.find(strict); at != std::string::npos; at = log.find(strict, at + 1)) ++placements;
  EXPECT_EQ(placements, 2u) << log;  // mapper, image_registrator

  progress.clear();
  options.force = true;
  options.second_pass = false;
  r = RunSfm(options);
  EXPECT_EQ(r.num_registered_images, 2);
  EXPECT_EQ(r.left_out, std::vector<std::string>{"c.jpg"});
  EXPECT_TRUE(said("sfm: left out: c.jpg"));
  EXPECT_TRUE(said("warning: only 2 of 3 photos (66 %) are in the model; try --matcher exhaustive"));
}

// Photos the second pass cannot register (they see too few of the model's points) are tried
// again as the model grows: pass 3 triangulates the model's points and registers again, adding
// d.jpg; then every photo is in, no pass 4 runs, and the model is adjusted. Each pass says what it
// added.
TEST(ColmapRunner, MorePassesRegisterWhatTheSecondLeftOut) {
  TempDir dir("passes");
  const fs::path first = dir.path() / "first", second = dir.path() / "second", full = dir.path() / "full";
  WriteNamedModel(first, {"a.jpg", "b.jpg"});
  WriteNamedModel(second, {"a.jpg", "b.jpg", "c.jpg"});
  WriteNamedModel(full, {"a.jpg", "b.jpg", "c.jpg", "d.jpg"});
  const fs::path once = dir.path() / "registered_once";
  const std::string script = StrCat(R"SH(#!/bin/sh
PATH=/usr/bin:/bin:$PATH
step="$1"
echo "fake colmap $step"
while [ $# -gt 0 ]; do
  case "$1" in --output_path) out="$2";; --input_path) in="$2";; esac; shift
done
case "$step" in
  mapper) mkdir -p "$out/0" && cp ")SH", first.string(), R"SH("/* "$out/0/" ;;
  point_triangulator) cp "$in"/* "$out/" ;;
  image_registrator) if [ -e ")SH", once.string(), R"SH(" ]; then cp ")SH", full.string(), R"SH("/* "$out/"; else cp ")SH",
                                    second.string(), R"SH("/* "$out/"; touch ")SH", once.string(), R"SH("; fi ;;
esac
exit 0
)SH");
  SfmOptions options;
  options.images = dir.path() / "photos";
  for (const char* name : {"a.jpg", "b.jpg", "c.jpg", "d.jpg"}) WritePhoto(options.images / name);
  options.workspace = dir.path() / "work";
  options.colmap_binary = (dir.path() / "bin" / "colmap").string();
  WriteExecutable(options.colmap_binary, script);
  options.exhaustive_max_images = 1;  // sequential
  options.min_registered_images = 2;
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };
  const auto said = [&](const std::string& text) { return Said(progress, text); };

  const SfmResult r = RunSfm(options);
  EXPECT_EQ(r.num_registered_images, 4);
  EXPECT_TRUE(r.left_out.empty());
  EXPECT_EQ(r.passes, (std::vector<int>{1, 1}));
  EXPECT_TRUE(said("sfm: pass 2 registered 1 more (3/4)"));
  EXPECT_TRUE(said("sfm: pass 3 registered 1 more (4/4)"));
  EXPECT_FALSE(said("pass 4"));
  const std::string log = ReadFile(options.workspace / "colmap" / "colmap.log");
  EXPECT_NE(log.find("fake colmap point_triangulator"), std::string::npos) << log;
  EXPECT_NE(log.rfind("fake colmap bundle_adjuster"), log.find("fake colmap bundle_adjuster")) << "adjusted after pass 3";
}

// A run of photos a.jpg to d.jpg, matched in sequence first, with a fake colmap whose mapper
// makes `before` until every pair was matched (which touches `marker`), then `after`.
SfmOptions FakeEveryPairRun(const fs::path& dir, const fs::path& before, const fs::path& after, const fs::path& marker) {
  const std::string script = StrCat(R"SH(#!/bin/sh
PATH=/usr/bin:/bin:$PATH
step="$1"
echo "fake colmap $step"
while [ $# -gt 0 ]; do [ "$1" = "--output_path" ] && out="$2"; shift; done
case "$step" in
  exhaustive_matcher) touch ")SH", marker.string(), R"SH(" ;;
  mapper) mkdir -p "$out/0"
    if [ -e ")SH", marker.string(), R"SH(" ]; then cp ")SH", after.string(), R"SH("/* "$out/0/"; else cp ")SH",
                                    before.string(), R"SH("/* "$out/0/"; fi ;;
esac
exit 0
)SH");
  SfmOptions options;
  options.images = dir / "photos";
  for (const char* name : {"a.jpg", "b.jpg", "c.jpg", "d.jpg"}) WritePhoto(options.images / name);
  options.workspace = dir / "work";
  options.colmap_binary = (dir / "bin" / "colmap").string();
  WriteExecutable(options.colmap_binary, script);
  options.exhaustive_max_images = 2;  // sequential first
  options.single_camera = false;
  return options;
}

// Photos not taken in order: sequential matching leaves most of them out of the model, so the
// run matches every pair and maps again (the fake's mapper then finds them all).
TEST(ColmapRunner, PhotosNotInOrderFallBackToEveryPair) {
  TempDir dir("unordered");
  const fs::path first = dir.path() / "first", full = dir.path() / "full";
  WriteNamedModel(first, {"a.jpg"});
  WriteNamedModel(full, {"a.jpg", "b.jpg", "c.jpg", "d.jpg"});
  const fs::path marker = dir.path() / "matched_all";
  SfmOptions options = FakeEveryPairRun(dir.path(), first, full, marker);
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };
  const SfmResult r = RunSfm(options);
  EXPECT_EQ(r.num_registered_images, 4);
  EXPECT_TRUE(fs::exists(marker));
  EXPECT_NE(std::find(progress.begin(), progress.end(),
                      "sfm: sequential matching put only 1 of 4 photos in a model, so they were not taken in order: "
                      "matching every pair and mapping again"),
            progress.end());
  const std::string log = ReadFile(options.workspace / "colmap" / "colmap.log");
  EXPECT_EQ(log.find("fake colmap matches_importer"), std::string::npos) << "no second pass after matching every pair";

  // --matcher sequential means it: no fallback.
  fs::remove(marker);
  options.force = true;
  options.matcher = "sequential";
  options.second_pass = false;
  try {
    RunSfm(options);
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.value(), "1 of 4");
  }
  EXPECT_FALSE(fs::exists(marker));
}

// Under a time budget auto matches every pair only where that takes at most half the time left;
// without one, up to --exhaustive-max (40) photos.
TEST(ColmapRunner, ABudgetTooShortForEveryPairMatchesInSequence) {
  TempDir dir("budget_pairs");
  const fs::path first = dir.path() / "first";
  WriteNamedModel(first, {"a.jpg", "b.jpg", "c.jpg", "d.jpg"});
  SfmOptions options = FakeEveryPairRun(dir.path(), first, first, dir.path() / "unused");
  options.exhaustive_max_images = SfmOptions().exhaustive_max_images;
  EXPECT_EQ(options.exhaustive_max_images, 40);
  options.num_threads = 2;
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };
  const auto log_has = [&](const std::string& text) {
    return ReadFile(options.workspace / "colmap" / "colmap.log").find(text) != std::string::npos;
  };
  // 4 photos: 6 pairs, ~1.7 s at 0.28 s a pair on 2 threads.
  options.seconds_left = [] { return 3.0; };
  RunSfm(options);
  EXPECT_TRUE(log_has("fake colmap sequential_matcher"));
  EXPECT_FALSE(log_has("fake colmap exhaustive_matcher"));
  EXPECT_TRUE(Said(progress, "sfm: every pair of the 4 photos would take about 1 s, more than half of what the time "
                             "budget leaves: matching in sequence"));
  progress.clear();
  options.force = true;
  options.seconds_left = [] { return 4.0; };
  RunSfm(options);
  EXPECT_TRUE(log_has("fake colmap exhaustive_matcher"));
  EXPECT_FALSE(Said(progress, "matching in sequence"));
}

// A model that looks wrong (check_model: for perf run, a ghost or cameras that do not look at a
// common point) after sequential matching is made again from every pair, and the new one kept
// where it looks right, though it holds fewer photos; where it looks wrong too, the first is
// kept, with a warning.
TEST(ColmapRunner, AModelThatLooksWrongIsMadeAgainFromEveryPair) {
  TempDir dir("wrong");
  const fs::path first = dir.path() / "first", remade = dir.path() / "remade";
  WriteNamedModel(first, {"a.jpg", "b.jpg", "c.jpg", "d.jpg"});
  WriteNamedModel(remade, {"a.jpg", "b.jpg", "c.jpg"});
  const fs::path marker = dir.path() / "matched_all";
  SfmOptions options = FakeEveryPairRun(dir.path(), first, remade, marker);
  bool remade_looks_wrong = false;
  options.check_model = [&](const fs::path& model) -> std::string {
    const size_t n = colmap::ReadReconstruction(model).images.size();
    return n == 4 ? "only 40 % of its cameras look at a common point" : remade_looks_wrong ? "it holds 1 ghost group" : "";
  };
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };
  SfmResult r = RunSfm(options);
  EXPECT_EQ(r.num_registered_images, 3);
  EXPECT_TRUE(r.exhaustive);
  EXPECT_TRUE(r.doubt.empty()) << r.doubt;
  EXPECT_TRUE(Said(progress, "sfm: the model of 4 photos looks wrong (only 40 % of its cameras look at a common point): "
                             "matching every pair and mapping again"));
  EXPECT_TRUE(Said(progress, "sfm: the model from every pair (3 photos) looks right: it is kept"));

  fs::remove(marker);
  progress.clear();
  options.force = true;
  remade_looks_wrong = true;
  r = RunSfm(options);
  EXPECT_EQ(r.num_registered_images, 4);
  EXPECT_EQ(r.doubt, "only 40 % of its cameras look at a common point");
  EXPECT_TRUE(Said(progress, "sfm: the model from every pair looks wrong too (it holds 1 ghost group): keeping the first"));
  EXPECT_TRUE(Said(progress, "sfm: warning: the model looks wrong (only 40 % of its cameras look at a common point)"));
  EXPECT_EQ(colmap::ReadReconstruction(r.sparse_dir).images.size(), 4u);

  // Under a time budget the model is made again all the same; where the budget cannot afford it,
  // the run says it passes the budget.
  for (const double left : {1e6, -5.0}) {
    fs::remove(marker);
    progress.clear();
    remade_looks_wrong = false;
    options.seconds_left = [left] { return left; };
    r = RunSfm(options);
    EXPECT_TRUE(fs::exists(marker)) << left;
    EXPECT_EQ(r.num_registered_images, 3) << left;
    EXPECT_TRUE(r.exhaustive) << left;
    bool said = false;
    for (const std::string& line : progress) {
      said = said || (line.find("matching every pair and mapping again will take about") != std::string::npos &&
                      line.find("more than the time budget leaves (0 s): the run passes its budget") != std::string::npos);
    }
    EXPECT_EQ(said, left < 0) << left;
  }
}

// Photos from two zoom settings of one camera and a crop without EXIF: three cameras, each
// extracted with its own image list; photos that all agree: one extraction, one camera.
TEST(ColmapRunner, PhotosShareACameraOnlyWhereSizeAndExifAgree) {
  TempDir dir("groups");
  const fs::path photos = dir.path() / "photos";
  WriteTaggedPhoto(photos / "a.jpg", 64, 48, "Canon", 35.f);
  WriteTaggedPhoto(photos / "b.jpg", 64, 48, "Canon", 35.f);
  WriteTaggedPhoto(photos / "c.jpg", 64, 48, "Canon", 50.f);
  WriteTaggedPhoto(photos / "sub" / "d.png", 40, 30, "", 0.f);
  const std::vector<std::string> names = {"a.jpg", "b.jpg", "c.jpg", "sub/d.png"};
  const std::vector<CameraGroup> groups = GroupByCamera(names, ReadPhotoTags(photos, names));
  ASSERT_EQ(groups.size(), 3u);
  EXPECT_EQ(groups[0].names, (std::vector<std::string>{"a.jpg", "b.jpg"}));
  EXPECT_EQ(groups[0].description, "64x48, Canon Model 1, 35 mm");
  EXPECT_EQ(groups[1].names, std::vector<std::string>{"c.jpg"});
  EXPECT_EQ(groups[2].description, "40x30, no EXIF camera");
  EXPECT_EQ(DescribeGroups(groups),
            "3 cameras from the photos' size and EXIF: 2 x 64x48, Canon Model 1, 35 mm; 1 x 64x48, Canon Model 1, "
            "50 mm; 1 x 40x30, no EXIF camera");

  SfmOptions options;
  options.images = photos;
  options.workspace = dir.path() / "work";
  options.colmap_binary = (dir.path() / "bin" / "colmap").string();
  WriteExecutable(options.colmap_binary, kFakeColmap);
  options.min_registered_images = 2;
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };
  RunSfm(options);
  EXPECT_NE(std::find(progress.begin(), progress.end(), "sfm: " + DescribeGroups(groups)), progress.end());
  const std::string log = ReadFile(options.workspace / "colmap" / "colmap.log");
  size_t runs = 0;
  for (size_t at = log.find("arg=[feature_extractor]"); at != std::string::npos; at = log.find("arg=[feature_extractor]", at + 1)) ++runs;
  EXPECT_EQ(runs, 3u);
  EXPECT_EQ(ReadFile(options.workspace / "colmap" / "camera_1_images.txt"), "a.jpg\nb.jpg\n");
  EXPECT_EQ(ReadFile(options.workspace / "colmap" / "camera_3_images.txt"), "sub/d.png\n");
  EXPECT_NE(log.find("arg=[--image_list_path]"), std::string::npos);

  fs::remove(photos / "c.jpg");
  fs::remove_all(photos / "sub");
  options.force = true;
  RunSfm(options);
  const std::string log2 = ReadFile(options.workspace / "colmap" / "colmap.log").substr(log.size());
  EXPECT_EQ(log2.find("arg=[--image_list_path]"), std::string::npos) << "one group: one plain extraction";
}

TEST(CaptureOrder, TimesTellWhetherTheNamesFollowTheCapture) {
  const std::string t0 = "2026:05:01 10:00:00", t1 = "2026:05:01 10:00:07", t2 = "2026:05:01 10:01:00",
                    t3 = "2026:05:02 09:00:00";
  CaptureOrder o = OrderFromTimes({t0, t1, t1, t2, t3});  // a burst of equal times is in order
  EXPECT_TRUE(o.Known());
  EXPECT_TRUE(o.NamesFollowTime());
  EXPECT_EQ(o.backwards, 0);
  o = OrderFromTimes({t3, t1, t2, t0});
  EXPECT_TRUE(o.Known());
  EXPECT_FALSE(o.NamesFollowTime());
  EXPECT_EQ(o.pairs, 3);
  EXPECT_EQ(o.backwards, 2);
  EXPECT_EQ(o.Describe(), "the EXIF capture times do not follow the file names (2 of 3 consecutive photos by name go "
                          "back in time): matching every pair");
  o = OrderFromTimes({t0, "", t1, t2});  // 3 of 4 carry a time: under 90 %
  EXPECT_FALSE(o.Known());
  EXPECT_FALSE(o.NamesFollowTime());
  // One photo of 21 out of place: 1 of 20 pairs goes back, within the 10 % allowed.
  std::vector<std::string> walk;
  for (int i = 0; i < 21; ++i) walk.push_back(StrCat("2026:05:01 10:", i < 10 ? "0" : "", i, ":00"));
  std::swap(walk[5], walk[20]);
  o = OrderFromTimes(walk);
  EXPECT_EQ(o.backwards, 2);
  EXPECT_TRUE(o.NamesFollowTime()) << o.Describe();
  std::swap(walk[1], walk[15]);
  EXPECT_FALSE(OrderFromTimes(walk).NamesFollowTime());
}

// Beyond the exhaustive limit, capture times that go against the names mean matching every pair
// at once (no sequential pass to waste); times in name order mean sequential matching.
TEST(ColmapRunner, CaptureTimesAgainstTheNamesMeanEveryPair) {
  TempDir dir("times");
  const fs::path photos = dir.path() / "photos";
  const std::vector<std::string> times = {"2026:05:01 10:00:30", "2026:05:01 10:00:10", "2026:05:01 10:00:20",
                                          "2026:05:01 10:00:00"};
  const std::vector<std::string> names = {"a.jpg", "b.jpg", "c.jpg", "d.jpg"};
  for (size_t i = 0; i < names.size(); ++i) WriteTaggedPhoto(photos / names[i], 64, 48, "Canon", 35.f, times[i]);
  SfmOptions options;
  options.images = photos;
  options.workspace = dir.path() / "work";
  options.colmap_binary = (dir.path() / "bin" / "colmap").string();
  WriteExecutable(options.colmap_binary, kFakeColmap);
  options.exhaustive_max_images = 2;
  options.min_registered_images = 2;
  options.second_pass = false;
  std::vector<std::string> progress;
  options.progress = [&](const std::string& line) { progress.push_back(line); };
  const auto said = [&](const std::string& text) { return Said(progress, text); };
  RunSfm(options);
  std::string log = ReadFile(options.workspace / "colmap" / "colmap.log");
  EXPECT_NE(log.find("arg=[exhaustive_matcher]"), std::string::npos) << log;
  EXPECT_EQ(log.find("arg=[sequential_matcher]"), std::string::npos) << log;
  EXPECT_TRUE(said("sfm: the EXIF capture times do not follow the file names (2 of 3"));

  // The same photos with their times in name order.
  std::vector<std::string> sorted = times;
  std::sort(sorted.begin(), sorted.end());
  for (size_t i = 0; i < names.size(); ++i) WriteTaggedPhoto(photos / names[i], 64, 48, "Canon", 35.f, sorted[i]);
  progress.clear();
  options.force = true;
  RunSfm(options);
  log = ReadFile(options.workspace / "colmap" / "colmap.log");
  EXPECT_NE(log.find("arg=[sequential_matcher]"), std::string::npos) << log;
  EXPECT_TRUE(said("sfm: the EXIF capture times follow the file names (0 of 3"));
}

TEST(ColmapRunner, FailingStepReportsExitCodeAndLogTail) {
  TempDir dir("failing");
  const SfmOptions options = WithFakeColmap(dir,
                                            "#!/bin/sh\n"
                                            "i=0; while [ $i -lt 30 ]; do echo \"output line $i\"; i=$((i+1)); done\n"
                                            "echo 'ERROR: something broke' >&2\n"
                                            "exit 3\n");
  try {
    RunSfm(options);
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    const std::string msg = e.what();
    const fs::path log = options.workspace / "colmap" / "colmap.log";
    EXPECT_EQ(e.path(), log.string());
    EXPECT_NE(msg.find("feature_extractor"), std::string::npos) << msg;
    EXPECT_NE(msg.find("exit code 3"), std::string::npos) << msg;
    EXPECT_NE(msg.find("ERROR: something broke"), std::string::npos) << msg;
    EXPECT_NE(msg.find("output line 29"), std::string::npos) << msg;
    EXPECT_EQ(msg.find("output line 10"), std::string::npos) << msg;  // only the tail
    EXPECT_NE(ReadFile(log).find("output line 0"), std::string::npos);
  }
}

// A step that goes quiet (a COLMAP that hangs) is stopped after the idle limit and reported as
// stuck, with its log's tail, instead of holding the run forever.
TEST(ColmapRunner, AStepThatPrintsNothingIsStoppedAsStuck) {
  TempDir dir("stuck");
  SfmOptions options = WithFakeColmap(dir, "#!/bin/sh\necho \"reading $1\"\nexec sleep 60\n");
  options.idle_timeout_seconds = 0.5;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    RunSfm(options);
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("feature_extractor printed nothing for 0.5 s"), std::string::npos) << msg;
    EXPECT_NE(msg.find("reading feature_extractor"), std::string::npos) << msg;  // the log's tail
    EXPECT_NE(msg.find("--colmap-idle-timeout"), std::string::npos) << msg;
    EXPECT_NE(ReadFile(options.workspace / "colmap" / "colmap.log").find("stopped: no output for 0.5 s"),
              std::string::npos);
  }
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 10.0);
}

TEST(ColmapRunner, CheckRejectsANonPositiveIdleTimeout) {
  SfmOptions options;
  options.images = "photos";
  options.workspace = "work";
  options.idle_timeout_seconds = 0;
  try {
    options.Check();
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "--colmap-idle-timeout");
  }
}

}  // namespace
}  // namespace perf
