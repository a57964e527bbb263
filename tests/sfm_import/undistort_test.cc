// Undistorter against COLMAP's forward model: known 3D points are projected with the distorted
// camera (camera_models.h) and with the output pinhole, and the undistorted image must show
// them where the pinhole says. Apply goes through OpenCV's tables and MapToDistorted through
// COLMAP's formula, so agreement between the two also checks that the models match.
#include "sfm_import/undistort.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "common/errors.h"
#include "sfm_import/camera_models.h"

namespace perf {
namespace {

using colmap::CameraModelId;

struct TestCamera {
  std::string label;
  colmap::Camera camera;
};

colmap::Camera MakeCamera(CameraModelId id, uint64_t width, uint64_t height,
                          std::vector<double> params) {
  colmap::Camera camera;
  camera.camera_id = 1;
  camera.model_id = static_cast<int>(id);
  camera.width = width;
  camera.height = height;
  camera.params = std::move(params);
  return camera;
}

// Realistic cameras: the perspective ones like mip-NeRF 360's bonsai (800 x 533, OPENCV with
// k1 = -0.126, k2 = 0.12), the fisheye ones wide (f = 300 on 640 px: about 120 degrees across),
// with fx != fy and off-centre principal points where the model allows.
std::vector<TestCamera> DistortedCameras() {
  return {
      {"SIMPLE_RADIAL", MakeCamera(CameraModelId::kSimpleRadial, 800, 533,
                                   {700, 399.1, 267.2, -0.08})},
      {"SIMPLE_RADIAL_pincushion", MakeCamera(CameraModelId::kSimpleRadial, 800, 533,
                                              {700, 400, 266.5, 0.1})},
      {"RADIAL", MakeCamera(CameraModelId::kRadial, 800, 533, {700, 399.1, 267.2, -0.126, 0.12})},
      {"OPENCV", MakeCamera(CameraModelId::kOpenCV, 800, 533,
                            {700, 705, 401.3, 265.2, -0.126, 0.12, 0.0012, -0.0008})},
      {"FULL_OPENCV",
       MakeCamera(CameraModelId::kFullOpenCV, 800, 533,
                  {700, 705, 401.3, 265.2, -0.126, 0.12, 0.0012, -0.0008, 0.01, 0.03, -0.02,
                   0.01})},
      {"OPENCV_FISHEYE", MakeCamera(CameraModelId::kOpenCVFisheye, 640, 480,
                                    {300, 305, 322.4, 238.9, 0.05, -0.02, 0.004, -0.001})},
      {"SIMPLE_RADIAL_FISHEYE",
       MakeCamera(CameraModelId::kSimpleRadialFisheye, 640, 480, {300, 320, 240, 0.03})},
      {"RADIAL_FISHEYE", MakeCamera(CameraModelId::kRadialFisheye, 640, 480,
                                    {300, 318.7, 241.3, 0.03, -0.01})},
      // Folds over inside the image: r (1 - 0.3 r^2) peaks at r = 1.054, well inside the
      // corners; only the part within the fold is usable.
      {"SIMPLE_RADIAL_folding", MakeCamera(CameraModelId::kSimpleRadial, 800, 600,
                                           {400, 400, 300, -0.3})},
  };
}

std::string Label(const testing::TestParamInfo<TestCamera>& info) { return info.param.label; }
void PrintTo(const TestCamera& c, std::ostream* os) { *os << c.label; }

// Projects a camera-frame point through the distorted camera (COLMAP's formula).
void ProjectDistorted(const colmap::Camera& camera, const double X[3], double* x, double* y) {
  colmap::ImgFromCam(static_cast<CameraModelId>(camera.model_id), camera.params.data(), X[0],
                     X[1], X[2], x, y);
}

void ProjectPinhole(const PinholeIntrinsics& p, const double X[3], double* x, double* y) {
  *x = p.fx * X[0] / X[2] + p.cx;
  *y = p.fy * X[1] / X[2] + p.cy;
}

// 3D points whose pinhole projections spread over the output image (fractions 0.1..0.9 of
// each side), at assorted depths.
std::vector<std::array<double, 3>> PointsInView(const PinholeIntrinsics& p) {
  std::vector<std::array<double, 3>> points;
  for (double fy : {0.1, 0.3, 0.5, 0.7, 0.9}) {
    for (double fx : {0.1, 0.3, 0.5, 0.7, 0.9}) {
      const double depth = 0.7 + 3 * fx + 5 * fy;
      const double u = (fx * p.width - p.cx) / p.fx, v = (fy * p.height - p.cy) / p.fy;
      points.push_back({u * depth, v * depth, depth});
    }
  }
  return points;
}

class UndistortDistorted : public testing::TestWithParam<TestCamera> {};

TEST_P(UndistortDistorted, OutputIsAPinholeOfTheSameSize) {
  const colmap::Camera& camera = GetParam().camera;
  const Undistorter u = Undistorter::Create(camera, "test camera");
  EXPECT_FALSE(u.is_identity());
  EXPECT_EQ(u.pinhole().width, static_cast<int>(camera.width));
  EXPECT_EQ(u.pinhole().height, static_cast<int>(camera.height));
  EXPECT_GT(u.pinhole().fx, 0);
  EXPECT_GT(u.pinhole().fy, 0);
}

TEST_P(UndistortDistorted, MapToDistortedFollowsColmapProjection) {
  const colmap::Camera& camera = GetParam().camera;
  const Undistorter u = Undistorter::Create(camera, "test camera");
  for (const auto& X : PointsInView(u.pinhole())) {
    double xd, yd, xu, yu, mx, my;
    ProjectDistorted(camera, X.data(), &xd, &yd);
    ProjectPinhole(u.pinhole(), X.data(), &xu, &yu);
    u.MapToDistorted(xu, yu, &mx, &my);
    EXPECT_NEAR(mx, xd, 1e-9) << "point " << X[0] << ", " << X[1] << ", " << X[2];
    EXPECT_NEAR(my, yd, 1e-9) << "point " << X[0] << ", " << X[1] << ", " << X[2];
  }
}

// The inverse map sends each distorted pixel centre to the pinhole pixel that MapToDistorted
// sends back to it (where the model is invertible), and the known projection of a 3D point
// lands where the point projects in the pinhole.
TEST_P(UndistortDistorted, MapFromDistortedInvertsMapToDistorted) {
  const colmap::Camera& camera = GetParam().camera;
  const Undistorter u = Undistorter::Create(camera, "test camera");
  std::vector<float> mx, my;
  u.MapFromDistorted(&mx, &my);
  const int w = static_cast<int>(camera.width), h = static_cast<int>(camera.height);
  ASSERT_EQ(mx.size(), static_cast<size_t>(w) * h);
  int valid = 0, checked = 0;
  for (int j = 0; j < h; j += 7) {
    for (int i = 0; i < w; i += 7) {
      const size_t k = static_cast<size_t>(j) * w + i;
      if (std::isnan(mx[k])) continue;
      ++valid;
      double xd, yd;
      u.MapToDistorted(mx[k], my[k], &xd, &yd);
      EXPECT_NEAR(xd, i + 0.5, 2e-3) << "pixel " << i << ", " << j;
      EXPECT_NEAR(yd, j + 0.5, 2e-3) << "pixel " << i << ", " << j;
      ++checked;
    }
  }
  // The centre of the photo always has an inverse; the folding camera loses its corners only.
  EXPECT_GT(valid, checked / 2);
  EXPECT_FALSE(std::isnan(mx[static_cast<size_t>(h / 2) * w + w / 2]));
  for (const auto& X : PointsInView(u.pinhole())) {
    double xd, yd, xu, yu;
    ProjectDistorted(camera, X.data(), &xd, &yd);
    ProjectPinhole(u.pinhole(), X.data(), &xu, &yu);
    // The pixel whose centre is nearest to the distorted projection maps near the pinhole one
    // (within the pinhole's scale of half a distorted pixel).
    const int i = static_cast<int>(xd), j = static_cast<int>(yd);
    if (i < 0 || j < 0 || i >= w || j >= h) continue;
    const size_t k = static_cast<size_t>(j) * w + i;
    ASSERT_FALSE(std::isnan(mx[k]));
    EXPECT_NEAR(mx[k], xu, 2.0) << "point " << X[0] << ", " << X[1] << ", " << X[2];
    EXPECT_NEAR(my[k], yu, 2.0) << "point " << X[0] << ", " << X[1] << ", " << X[2];
  }
}

// Every output pixel centre samples the input between its outermost pixel centres (so also
// inside [0, W] x [0, H]), and the fit is tight: some border pixel lands on the edge.
TEST_P(UndistortDistorted, KeepsOnlyValidPixelsAndAllOfThem) {
  const colmap::Camera& camera = GetParam().camera;
  const Undistorter u = Undistorter::Create(camera, "test camera");
  const double w = static_cast<double>(camera.width), h = static_cast<double>(camera.height);
  double min_margin = 1e9;
  for (int j = 0; j < u.pinhole().height; ++j) {
    for (int i = 0; i < u.pinhole().width; ++i) {
      double xd, yd;
      u.MapToDistorted(i + 0.5, j + 0.5, &xd, &yd);
      ASSERT_TRUE(xd >= 0 && xd <= w && yd >= 0 && yd <= h)
          << "output pixel (" << i << ", " << j << ") samples (" << xd << ", " << yd << ")";
      min_margin = std::min({min_margin, xd - 0.5, w - 0.5 - xd, yd - 0.5, h - 0.5 - yd});
    }
  }
  EXPECT_GE(min_margin, -1e-3);
  if (GetParam().label != "SIMPLE_RADIAL_folding") {
    EXPECT_LE(min_margin, 0.01) << "the output crops more of the input than it has to";
  }
}

// The folding camera: the output must stay inside the fold (radius 1/sqrt(0.9) in normalised
// coordinates), where the model is still one-to-one, and reach it.
TEST(UndistortFolding, StaysWithinTheInvertibleRadius) {
  const colmap::Camera camera =
      MakeCamera(CameraModelId::kSimpleRadial, 800, 600, {400, 400, 300, -0.3});
  const Undistorter u = Undistorter::Create(camera, "test camera");
  const PinholeIntrinsics& p = u.pinhole();
  double max_r = 0;
  for (double x : {0.5, p.width - 0.5}) {
    for (double y : {0.5, p.height - 0.5}) {
      max_r = std::max(max_r, std::hypot((x - p.cx) / p.fx, (y - p.cy) / p.fy));
    }
  }
  EXPECT_LE(max_r, 1 / std::sqrt(0.9));
  EXPECT_GE(max_r, 0.999 / std::sqrt(0.9));
}

// Normalised coordinates (u, v) of the ray that camera `camera` images at pixel (xd, yd):
// Newton's method on COLMAP's projection, from a nearby guess.
void RayThroughPixel(const colmap::Camera& camera, double xd, double yd, double* u, double* v) {
  const auto id = static_cast<CameraModelId>(camera.model_id);
  const auto project = [&](double a, double b, double* x, double* y) {
    colmap::ImgFromCam(id, camera.params.data(), a, b, 1.0, x, y);
  };
  constexpr double h = 1e-7;
  for (int iteration = 0; iteration < 20; ++iteration) {
    double x, y, xa, ya, xb, yb;
    project(*u, *v, &x, &y);
    if (std::hypot(x - xd, y - yd) < 1e-10) return;
    project(*u + h, *v, &xa, &ya);
    project(*u, *v + h, &xb, &yb);
    const double j00 = (xa - x) / h, j10 = (ya - y) / h, j01 = (xb - x) / h, j11 = (yb - y) / h;
    const double det = j00 * j11 - j01 * j10;
    *u -= (j11 * (x - xd) - j01 * (y - yd)) / det;
    *v -= (-j10 * (x - xd) + j00 * (y - yd)) / det;
  }
}

// Each 3D point gets a Gaussian blob that is round in the output, centred on the point's pinhole
// projection xu, drawn into the input through the inverse of COLMAP's distortion (so the blob in
// the input is warped, and centred on the point's distorted projection). After Apply, the blob's
// centroid must be at xu, to remap's 1/32 px position steps (0.015 px seen; 0.023 px next to the
// fold of the folding camera). (A blob drawn round in the input would come out warped, and a
// warp moves a centroid by a second-order amount: 0.17 px near the fisheye edges here.)
TEST_P(UndistortDistorted, ApplyMovesContentToThePinholeProjection) {
  const colmap::Camera& camera = GetParam().camera;
  const Undistorter u = Undistorter::Create(camera, "test camera");
  const PinholeIntrinsics& p = u.pinhole();

  // The blobs are far apart (a fifth of the image), so one image holds them all.
  Image in(static_cast<int>(camera.width), static_cast<int>(camera.height), 1);
  struct Blob {
    std::array<double, 3> X;
    double xu, yu, sigma;  // output pixels
  };
  std::vector<Blob> blobs;
  for (const auto& X : PointsInView(p)) {
    double xd, yd, xu, yu;
    ProjectDistorted(camera, X.data(), &xd, &yd);
    ProjectPinhole(p, X.data(), &xu, &yu);
    // Local scale of output -> input, to size the blob so that it is at least 2 px wide in both
    // images (narrower, bilinear interpolation would bias the centroid).
    double x1, y1, x2, y2;
    const double dx[3] = {X[0] + X[2] / p.fx, X[1], X[2]}, dy[3] = {X[0], X[1] + X[2] / p.fy, X[2]};
    ProjectDistorted(camera, dx, &x1, &y1);
    ProjectDistorted(camera, dy, &x2, &y2);
    const double det = (x1 - xd) * (y2 - yd) - (x2 - xd) * (y1 - yd);
    const double norm = std::hypot(x1 - xd, y1 - yd, std::hypot(x2 - xd, y2 - yd));
    const double sigma = 2 * std::max(1.0, norm / det);
    const double radius = 6 * sigma * norm + 2;  // input pixels
    for (int j = std::max(0, static_cast<int>(yd - radius));
         j <= std::min(in.height - 1, static_cast<int>(yd + radius)); ++j) {
      for (int i = std::max(0, static_cast<int>(xd - radius));
           i <= std::min(in.width - 1, static_cast<int>(xd + radius)); ++i) {
        double ru = X[0] / X[2], rv = X[1] / X[2];
        RayThroughPixel(camera, i + 0.5, j + 0.5, &ru, &rv);
        const double ox = p.fx * ru + p.cx - xu, oy = p.fy * rv + p.cy - yu;
        in.at(i, j, 0) += static_cast<float>(std::exp(-(ox * ox + oy * oy) / (2 * sigma * sigma)));
      }
    }
    blobs.push_back({X, xu, yu, sigma});
  }
  const Image out = u.Apply(in);
  for (const Blob& b : blobs) {
    double sum = 0, sx = 0, sy = 0;
    const double window = 6 * b.sigma;
    for (int j = std::max(0, static_cast<int>(b.yu - window));
         j <= std::min(p.height - 1, static_cast<int>(b.yu + window)); ++j) {
      for (int i = std::max(0, static_cast<int>(b.xu - window));
           i <= std::min(p.width - 1, static_cast<int>(b.xu + window)); ++i) {
        sum += out.at(i, j, 0);
        sx += out.at(i, j, 0) * (i + 0.5);
        sy += out.at(i, j, 0) * (j + 0.5);
      }
    }
    ASSERT_GT(sum, 0);
    EXPECT_NEAR(sx / sum, b.xu, 0.03) << "point " << b.X[0] << ", " << b.X[1] << ", " << b.X[2];
    EXPECT_NEAR(sy / sum, b.yu, 0.03) << "point " << b.X[0] << ", " << b.X[1] << ", " << b.X[2];
  }
}

// A smooth pattern, different in each channel, resampled everywhere: out(x) == in(MapToDistorted
// (x)) up to bilinear interpolation and remap's 1/32 px position steps, for 1 to 5 channels.
TEST_P(UndistortDistorted, ApplyResamplesEveryPixelAndChannel) {
  const colmap::Camera& camera = GetParam().camera;
  const Undistorter u = Undistorter::Create(camera, "test camera");
  const auto pattern = [](double x, double y, int c) {
    return 0.5 + 0.25 * std::sin(x / (23.0 + 4 * c) + 0.3 * c) +
           0.25 * std::cos(y / (17.0 + 3 * c) - 0.2);
  };
  for (int channels = 1; channels <= 5; ++channels) {
    Image in(static_cast<int>(camera.width), static_cast<int>(camera.height), channels);
    for (int j = 0; j < in.height; ++j) {
      for (int i = 0; i < in.width; ++i) {
        for (int c = 0; c < channels; ++c) {
          in.at(i, j, c) = static_cast<float>(pattern(i + 0.5, j + 0.5, c));
        }
      }
    }
    const Image out = u.Apply(in);
    ASSERT_EQ(out.channels, channels);
    double worst = 0;
    for (int j = 0; j < out.height; ++j) {
      for (int i = 0; i < out.width; ++i) {
        double xd, yd;
        u.MapToDistorted(i + 0.5, j + 0.5, &xd, &yd);
        // Where the sample sits within kInsideTolerancePx of the edge, the edge pixel is used.
        xd = std::clamp(xd, 0.5, in.width - 0.5);
        yd = std::clamp(yd, 0.5, in.height - 0.5);
        for (int c = 0; c < channels; ++c) {
          worst = std::max(worst, std::abs(out.at(i, j, c) - pattern(xd, yd, c)));
        }
      }
    }
    EXPECT_LT(worst, 1e-3) << channels << " channels";
  }
}

TEST_P(UndistortDistorted, ApplyRejectsImagesOfAnotherSize) {
  const colmap::Camera& camera = GetParam().camera;
  const Undistorter u = Undistorter::Create(camera, "cams.bin camera 1");
  const Image half(static_cast<int>(camera.width / 2), static_cast<int>(camera.height / 2), 3);
  try {
    u.Apply(half);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("cams.bin camera 1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(std::to_string(camera.width / 2) + "x"),
              std::string::npos)
        << e.what();
  }
}

INSTANTIATE_TEST_SUITE_P(Models, UndistortDistorted, testing::ValuesIn(DistortedCameras()),
                         Label);

TEST(UndistortPinhole, IsIdentity) {
  for (const colmap::Camera& camera :
       {MakeCamera(CameraModelId::kSimplePinhole, 800, 533, {700, 400, 266.5}),
        MakeCamera(CameraModelId::kPinhole, 800, 533, {700, 712, 401.2, 265.3})}) {
    const Undistorter u = Undistorter::Create(camera, "test camera");
    EXPECT_TRUE(u.is_identity());
    const colmap::FocalAndCentre fc = colmap::GetFocalAndCentre(
        static_cast<CameraModelId>(camera.model_id), camera.params.data());
    EXPECT_EQ(u.pinhole().width, 800);
    EXPECT_EQ(u.pinhole().height, 533);
    EXPECT_EQ(u.pinhole().fx, fc.fx);
    EXPECT_EQ(u.pinhole().fy, fc.fy);
    EXPECT_EQ(u.pinhole().cx, fc.cx);
    EXPECT_EQ(u.pinhole().cy, fc.cy);
    double xd, yd;
    u.MapToDistorted(12.25, 500.5, &xd, &yd);
    EXPECT_EQ(xd, 12.25);
    EXPECT_EQ(yd, 500.5);

    Image in(800, 533, 2);
    for (size_t k = 0; k < in.pixels.size(); ++k) in.pixels[k] = static_cast<float>(k % 977);
    const Image out = u.Apply(in);
    EXPECT_EQ(out.width, 800);
    EXPECT_EQ(out.height, 533);
    EXPECT_EQ(out.channels, 2);
    EXPECT_EQ(out.pixels, in.pixels);
  }
}

TEST(UndistortErrors, UnsupportedModelsPointToColmapImageUndistorter) {
  const std::vector<std::pair<colmap::Camera, std::string>> cases = {
      {MakeCamera(CameraModelId::kFOV, 640, 480, {300, 300, 320, 240, 0.9}), "FOV"},
      {MakeCamera(CameraModelId::kThinPrismFisheye, 640, 480,
                  {300, 300, 320, 240, 0, 0, 0, 0, 0, 0, 0, 0}),
       "THIN_PRISM_FISHEYE"},
      {MakeCamera(CameraModelId::kRadTanThinPrismFisheye, 640, 480,
                  {300, 300, 320, 240, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0}),
       "RAD_TAN_THIN_PRISM_FISHEYE"},
  };
  for (const auto& [camera, name] : cases) {
    try {
      Undistorter::Create(camera, "sparse/0/cameras.bin camera 1");
      ADD_FAILURE() << name << ": expected InputError";
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(name), std::string::npos) << what;
      EXPECT_NE(what.find("colmap image_undistorter"), std::string::npos) << what;
      EXPECT_NE(what.find("sparse/0/cameras.bin camera 1"), std::string::npos) << what;
    }
  }
}

TEST(UndistortErrors, UnknownModelId) {
  colmap::Camera camera = MakeCamera(CameraModelId::kPinhole, 640, 480, {300, 300, 320, 240});
  camera.model_id = 42;
  try {
    Undistorter::Create(camera, "cameras.txt camera 3");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("42"), std::string::npos) << what;
    EXPECT_NE(what.find("image_undistorter"), std::string::npos) << what;
    EXPECT_NE(what.find("cameras.txt camera 3"), std::string::npos) << what;
  }
}

TEST(UndistortErrors, WrongParameterCount) {
  const colmap::Camera camera =
      MakeCamera(CameraModelId::kOpenCV, 800, 533, {700, 705, 401.3, 265.2, -0.126, 0.12});
  try {
    Undistorter::Create(camera, "cameras.txt camera 2");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("OPENCV takes 8 parameters"), std::string::npos) << what;
    EXPECT_NE(what.find("6 values"), std::string::npos) << what;
  }
  // Pinhole models are checked too, although they need no resampling.
  EXPECT_THROW(Undistorter::Create(MakeCamera(CameraModelId::kPinhole, 800, 533, {700, 400, 266}),
                                   "c"),
               InputError);
}

TEST(UndistortErrors, BadValues) {
  const auto create = [](colmap::Camera camera) { Undistorter::Create(camera, "c"); };
  EXPECT_THROW(create(MakeCamera(CameraModelId::kSimpleRadial, 800, 533, {NAN, 400, 266, 0})),
               InputError);
  EXPECT_THROW(create(MakeCamera(CameraModelId::kSimpleRadial, 800, 533, {-700, 400, 266, 0})),
               InputError);
  EXPECT_THROW(create(MakeCamera(CameraModelId::kSimpleRadial, 0, 533, {700, 400, 266, 0})),
               InputError);
  EXPECT_THROW(create(MakeCamera(CameraModelId::kSimpleRadial, 40000, 533, {700, 400, 266, 0})),
               InputError);
  // Principal point outside the image.
  EXPECT_THROW(create(MakeCamera(CameraModelId::kSimpleRadial, 800, 533, {700, 900, 266, 0.01})),
               InputError);
  // Folds over 0.7 px from the principal point: nothing worth keeping.
  try {
    create(MakeCamera(CameraModelId::kSimpleRadial, 800, 600, {400, 400, 300, -1e5}));
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no usable pinhole view"), std::string::npos)
        << e.what();
  }
}

TEST(Undistort, MovedUndistorterKeepsWorking) {
  Undistorter a = Undistorter::Create(
      MakeCamera(CameraModelId::kRadial, 800, 533, {700, 399.1, 267.2, -0.126, 0.12}), "c");
  const PinholeIntrinsics p = a.pinhole();
  double x0, y0;
  a.MapToDistorted(100, 200, &x0, &y0);
  Undistorter b = std::move(a);
  double x1, y1;
  b.MapToDistorted(100, 200, &x1, &y1);
  EXPECT_EQ(x0, x1);
  EXPECT_EQ(y0, y1);
  EXPECT_EQ(b.pinhole().fx, p.fx);
  EXPECT_EQ(b.Apply(Image(800, 533, 1)).width, 800);
}

}  // namespace
}  // namespace perf
