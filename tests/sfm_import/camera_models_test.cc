// COLMAP camera models against numbers worked out by hand from COLMAP's formulas
// (src/colmap/sensor/models.h), the model table against COLMAP's ids, names and parameter
// counts, and the templated distortion under ceres::Jet against finite differences.
#include "sfm_import/camera_models.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#if __has_include(<ceres/jet.h>)
// Header-only: needs Eigen (linked) but not the Ceres library.
#include <ceres/jet.h>
#define PERF_HAVE_CERES_JET 1
#endif

namespace perf::colmap {
namespace {

// All hand computations below project the camera-frame point (0.4, -0.2, 2), i.e. the
// normalised coordinates
//   u = 0.2, v = -0.1, u^2 = 0.04, v^2 = 0.01, uv = -0.02,
//   r^2 = 0.05, r^4 = 0.0025, r^6 = 0.000125,
// with focal lengths 500 (x) and 450 (y, where the model has two) and principal point
// (320, 240), and the distortion coefficients
//   k1 = 0.1, k2 = -0.2, p1 = 0.01, p2 = -0.02, k3 = 0.4, k4 = 0.05, k5 = -0.1, k6 = 0.2
// for the perspective models, and k1 = 0.1, k2 = -0.05, k3 = 0.01, k4 = -0.002 for the fisheye
// models.
constexpr double kX = 0.4, kY = -0.2, kZ = 2.0;
// Fisheye: r = sqrt(0.05) = 0.22360679774997897, theta = atan(r) = 0.21998797739545945.
constexpr double kR = 0.22360679774997897;

struct Expected {
  CameraModelId id;
  std::vector<double> params;
  double x, y;
};

std::vector<Expected> HandComputed() {
  return {
      // x = 500 * 0.2 + 320, y = 500 * -0.1 + 240.
      {CameraModelId::kSimplePinhole, {500, 320, 240}, 420, 190},
      // y = 450 * -0.1 + 240.
      {CameraModelId::kPinhole, {500, 450, 320, 240}, 420, 195},
      // radial = k r^2 = 0.005: (u, v)(1 + 0.005) = (0.201, -0.1005).
      {CameraModelId::kSimpleRadial, {500, 320, 240, 0.1}, 420.5, 189.75},
      // radial = 0.1 * 0.05 - 0.2 * 0.0025 = 0.0045: (0.2009, -0.10045).
      {CameraModelId::kRadial, {500, 320, 240, 0.1, -0.2}, 420.45, 189.775},
      // radial = 0.0045;
      // du = u radial + 2 p1 uv + p2 (r^2 + 2 u^2) = 0.0009 - 0.0004 - 0.0026 = -0.0021,
      // dv = v radial + 2 p2 uv + p1 (r^2 + 2 v^2) = -0.00045 + 0.0008 + 0.0007 = 0.00105;
      // x = 500 * 0.1979 + 320, y = 450 * -0.09895 + 240.
      {CameraModelId::kOpenCV,
       {500, 450, 320, 240, 0.1, -0.2, 0.01, -0.02},
       418.95,
       195.4725},
      // radial = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
      //        = (1 + 0.005 - 0.0005 + 0.00005) / (1 + 0.0025 - 0.00025 + 0.000025)
      //        = 1.00455 / 1.002275 = 1.0022698361228206;
      // u' = u radial + 2 p1 uv + p2 (r^2 + 2 u^2) = 0.2 radial - 0.003,
      // v' = v radial + 2 p2 uv + p1 (r^2 + 2 v^2) = -0.1 radial + 0.0015;
      // x = 100 radial + 318.5, y = 240.675 - 45 radial.
      {CameraModelId::kFullOpenCV,
       {500, 450, 320, 240, 0.1, -0.2, 0.01, -0.02, 0.4, 0.05, -0.1, 0.2},
       418.72698361228206,
       195.57285737447307},
      // theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
      //         = 0.22102708864396458, scale = theta_d / r = 0.98846319015355321;
      // x = 500 * 0.2 scale + 320, y = 450 * -0.1 scale + 240.
      {CameraModelId::kOpenCVFisheye,
       {500, 450, 320, 240, 0.1, -0.05, 0.01, -0.002},
       418.84631901535532,
       195.51915644309011},
      // theta_d = theta (1 + k theta^2) = 0.22105260283678118, scale = 0.98857729309261115.
      {CameraModelId::kSimpleRadialFisheye,
       {500, 320, 240, 0.1},
       418.85772930926111,
       190.57113534536944},
      // theta_d = theta (1 + k1 theta^2 + k2 theta^4) = 0.22102684171692980,
      // scale = 0.98846208586228273.
      {CameraModelId::kRadialFisheye,
       {500, 320, 240, 0.1, -0.05},
       418.84620858622827,
       190.57689570688586},
  };
}

TEST(CameraModels, ImgFromCamMatchesHandComputedProjections) {
  for (const Expected& e : HandComputed()) {
    const CameraModelInfo* info = FindCameraModel(static_cast<int>(e.id));
    ASSERT_NE(info, nullptr);
    ASSERT_EQ(e.params.size(), static_cast<size_t>(info->num_params)) << info->name;
    double x, y;
    ImgFromCam(e.id, e.params.data(), kX, kY, kZ, &x, &y);
    EXPECT_NEAR(x, e.x, 1e-11) << info->name;
    EXPECT_NEAR(y, e.y, 1e-11) << info->name;
  }
}

TEST(CameraModels, FisheyeHandComputationInputs) {
  // The literals above, from their definitions.
  EXPECT_NEAR(kR, std::sqrt(0.05), 1e-16);
  EXPECT_NEAR(std::atan(kR), 0.21998797739545945, 1e-16);
}

TEST(CameraModels, NoDistortionOnTheOpticalAxis) {
  for (const Expected& e : HandComputed()) {
    double x, y;
    ImgFromCam(e.id, e.params.data(), 0.0, 0.0, 3.0, &x, &y);
    const FocalAndCentre fc = GetFocalAndCentre(e.id, e.params.data());
    EXPECT_EQ(x, fc.cx);
    EXPECT_EQ(y, fc.cy);
  }
}

// COLMAP's ids, names and parameter counts (src/colmap/sensor/models.h).
struct ColmapModel {
  int id;
  const char* name;
  int num_params;
  bool supported;
};
constexpr ColmapModel kColmapModels[] = {
    {0, "SIMPLE_PINHOLE", 3, true},
    {1, "PINHOLE", 4, true},
    {2, "SIMPLE_RADIAL", 4, true},
    {3, "RADIAL", 5, true},
    {4, "OPENCV", 8, true},
    {5, "OPENCV_FISHEYE", 8, true},
    {6, "FULL_OPENCV", 12, true},
    {7, "FOV", 5, false},
    {8, "SIMPLE_RADIAL_FISHEYE", 4, true},
    {9, "RADIAL_FISHEYE", 5, true},
    {10, "THIN_PRISM_FISHEYE", 12, false},
    {11, "RAD_TAN_THIN_PRISM_FISHEYE", 16, false},
};

TEST(CameraModels, TableMatchesColmap) {
  for (const ColmapModel& c : kColmapModels) {
    const CameraModelInfo* by_id = FindCameraModel(c.id);
    ASSERT_NE(by_id, nullptr) << c.name;
    EXPECT_EQ(static_cast<int>(by_id->id), c.id);
    EXPECT_EQ(by_id->name, c.name);
    EXPECT_EQ(by_id->num_params, c.num_params) << c.name;
    EXPECT_EQ(by_id->supported, c.supported) << c.name;
    EXPECT_EQ(FindCameraModel(c.name), by_id) << c.name;
    // The parameter list for messages names as many parameters as the model has.
    const std::string params(by_id->params);
    EXPECT_EQ(std::count(params.begin(), params.end(), ',') + 1, c.num_params) << c.name;
  }
}

TEST(CameraModels, UnknownIdsAndNames) {
  for (int id : {-1, 12, 99, 100, 1000}) EXPECT_EQ(FindCameraModel(id), nullptr) << id;
  for (const char* name : {"", "opencv", "PINHOLE ", "SPHERICAL", "DIVISION"}) {
    EXPECT_EQ(FindCameraModel(std::string_view(name)), nullptr) << "'" << name << "'";
  }
}

TEST(CameraModels, FocalAndCentre) {
  EXPECT_EQ(NumFocalParams(CameraModelId::kSimplePinhole), 3);
  EXPECT_EQ(NumFocalParams(CameraModelId::kSimpleRadial), 3);
  EXPECT_EQ(NumFocalParams(CameraModelId::kRadial), 3);
  EXPECT_EQ(NumFocalParams(CameraModelId::kSimpleRadialFisheye), 3);
  EXPECT_EQ(NumFocalParams(CameraModelId::kRadialFisheye), 3);
  for (CameraModelId id :
       {CameraModelId::kPinhole, CameraModelId::kOpenCV, CameraModelId::kOpenCVFisheye,
        CameraModelId::kFullOpenCV, CameraModelId::kFOV, CameraModelId::kThinPrismFisheye,
        CameraModelId::kRadTanThinPrismFisheye}) {
    EXPECT_EQ(NumFocalParams(id), 4) << static_cast<int>(id);
  }
  const double single[] = {500, 320, 240, 0.1};
  const FocalAndCentre s = GetFocalAndCentre(CameraModelId::kSimpleRadial, single);
  EXPECT_EQ(s.fx, 500);
  EXPECT_EQ(s.fy, 500);
  EXPECT_EQ(s.cx, 320);
  EXPECT_EQ(s.cy, 240);
  const double two[] = {500, 450, 320, 240, 0.9};
  const FocalAndCentre t = GetFocalAndCentre(CameraModelId::kFOV, two);
  EXPECT_EQ(t.fx, 500);
  EXPECT_EQ(t.fy, 450);
  EXPECT_EQ(t.cx, 320);
  EXPECT_EQ(t.cy, 240);
}

#ifdef PERF_HAVE_CERES_JET
// Derivatives of ImgFromCam with respect to every parameter and the point, through ceres::Jet,
// against central differences of the double version, and the Jet's value against the double.
TEST(CameraModels, JetDerivativesMatchFiniteDifferences) {
  constexpr int kMaxParams = 12;
  using Jet = ceres::Jet<double, kMaxParams + 3>;  // parameters, then x, y, z
  for (const Expected& e : HandComputed()) {
    const auto n = static_cast<int>(e.params.size());
    const double point[3] = {kX, kY, kZ};
    std::vector<Jet> params(n);
    for (int i = 0; i < n; ++i) params[i] = Jet(e.params[i], i);
    Jet jx, jy;
    ImgFromCam(e.id, params.data(), Jet(kX, kMaxParams), Jet(kY, kMaxParams + 1),
               Jet(kZ, kMaxParams + 2), &jx, &jy);
    double x, y;
    ImgFromCam(e.id, e.params.data(), kX, kY, kZ, &x, &y);
    EXPECT_NEAR(jx.a, x, 1e-12);  // not bit-exact: Jet arithmetic rounds differently
    EXPECT_NEAR(jy.a, y, 1e-12);

    const auto numeric = [&](int k, double* dx, double* dy) {
      std::vector<double> p = e.params;
      double q[3] = {point[0], point[1], point[2]};
      double& value = k < kMaxParams ? p[k] : q[k - kMaxParams];
      const double h = 1e-6 * std::max(1.0, std::abs(value));
      const double saved = value;
      double x1, y1, x0, y0;
      value = saved + h;
      ImgFromCam(e.id, p.data(), q[0], q[1], q[2], &x1, &y1);
      value = saved - h;
      ImgFromCam(e.id, p.data(), q[0], q[1], q[2], &x0, &y0);
      *dx = (x1 - x0) / (2 * h);
      *dy = (y1 - y0) / (2 * h);
    };
    for (int k = 0; k < kMaxParams + 3; ++k) {
      if (k >= n && k < kMaxParams) continue;
      double dx, dy;
      numeric(k, &dx, &dy);
      EXPECT_NEAR(jx.v[k], dx, 1e-6 * std::max(1.0, std::abs(dx)))
          << FindCameraModel(static_cast<int>(e.id))->name << " d x / d input " << k;
      EXPECT_NEAR(jy.v[k], dy, 1e-6 * std::max(1.0, std::abs(dy)))
          << FindCameraModel(static_cast<int>(e.id))->name << " d y / d input " << k;
    }
  }
}
#else
TEST(CameraModels, JetDerivativesMatchFiniteDifferences) {
  GTEST_SKIP() << "ceres/jet.h not found; install libceres-dev to run this test";
}
#endif

}  // namespace
}  // namespace perf::colmap
