// COLMAP camera models: parameter order, projection and distortion, exactly as COLMAP defines
// them (COLMAP's src/colmap/sensor/models.h), as structs of static functions templated on the
// scalar so one body serves double here and ceres::Jet in derivative tests. (The reconstruction
// sees undistorted pinhole cameras only: ray_math.h's PinholeCamera.)
//
// Conventions (stated once, used everywhere in PERF):
// - Camera frame: x right, y down, z forward (looking along +z). `cam_from_world` maps world
//   points into it.
// - Pixel coordinates: the upper-left corner of the image is (0, 0) and the centre of the
//   upper-left pixel is (0.5, 0.5) (COLMAP's convention). OpenCV puts that centre at (0, 0), so
//   principal points are shifted by -0.5 when handed to OpenCV.
#pragma once

#include <cmath>
#include <optional>
#include <string>
#include <string_view>

namespace perf::colmap {

enum class CameraModelId : int {
  kSimplePinhole = 0,        // f, cx, cy
  kPinhole = 1,              // fx, fy, cx, cy
  kSimpleRadial = 2,         // f, cx, cy, k
  kRadial = 3,               // f, cx, cy, k1, k2
  kOpenCV = 4,               // fx, fy, cx, cy, k1, k2, p1, p2
  kOpenCVFisheye = 5,        // fx, fy, cx, cy, k1, k2, k3, k4
  kFullOpenCV = 6,           // fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6
  kFOV = 7,                  // fx, fy, cx, cy, omega
  kSimpleRadialFisheye = 8,  // f, cx, cy, k
  kRadialFisheye = 9,        // f, cx, cy, k1, k2
  kThinPrismFisheye = 10,    // fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1
  kRadTanThinPrismFisheye = 11,  // fx, fy, cx, cy, k0..k5, p0, p1, s0..s3
};

struct CameraModelInfo {
  CameraModelId id;
  std::string_view name;   // COLMAP's name, e.g. "OPENCV"
  int num_params;
  bool supported;          // PERF can undistort it to a pinhole
  std::string_view params; // parameter order, for messages
};

// Every model COLMAP knows; nullptr / nullopt for unknown ids and names.
const CameraModelInfo* FindCameraModel(int id);
const CameraModelInfo* FindCameraModel(std::string_view name);

// Focal lengths and principal point of a parameter vector in any model (f is used for fx and
// fy where the model has one focal length).
struct FocalAndCentre {
  double fx, fy, cx, cy;
};
FocalAndCentre GetFocalAndCentre(CameraModelId id, const double* params);

// Distortion in normalised camera coordinates (u, v) = (X/Z, Y/Z): returns (du, dv) such that
// the distorted point is (u + du, v + dv), then pixel = f * distorted + c. Exactly COLMAP's
// formulas. `extra` points at the parameters after the focal lengths and principal point.
template <typename T>
void Distortion(CameraModelId id, const T* extra, T u, T v, T* du, T* dv) {
  using std::atan;
  using std::sqrt;
  const T u2 = u * u, v2 = v * v, uv = u * v, r2 = u2 + v2;
  switch (id) {
    case CameraModelId::kSimplePinhole:
    case CameraModelId::kPinhole:
      *du = T(0);
      *dv = T(0);
      return;
    case CameraModelId::kSimpleRadial: {
      const T radial = extra[0] * r2;
      *du = u * radial;
      *dv = v * radial;
      return;
    }
    case CameraModelId::kRadial: {
      const T radial = extra[0] * r2 + extra[1] * r2 * r2;
      *du = u * radial;
      *dv = v * radial;
      return;
    }
    case CameraModelId::kOpenCV: {
      const T k1 = extra[0], k2 = extra[1], p1 = extra[2], p2 = extra[3];
      const T radial = k1 * r2 + k2 * r2 * r2;
      *du = u * radial + T(2) * p1 * uv + p2 * (r2 + T(2) * u2);
      *dv = v * radial + T(2) * p2 * uv + p1 * (r2 + T(2) * v2);
      return;
    }
    case CameraModelId::kFullOpenCV: {
      const T k1 = extra[0], k2 = extra[1], p1 = extra[2], p2 = extra[3];
      const T k3 = extra[4], k4 = extra[5], k5 = extra[6], k6 = extra[7];
      const T r4 = r2 * r2, r6 = r4 * r2;
      const T radial = (T(1) + k1 * r2 + k2 * r4 + k3 * r6) / (T(1) + k4 * r2 + k5 * r4 + k6 * r6);
      *du = u * radial + T(2) * p1 * uv + p2 * (r2 + T(2) * u2) - u;
      *dv = v * radial + T(2) * p2 * uv + p1 * (r2 + T(2) * v2) - v;
      return;
    }
    case CameraModelId::kOpenCVFisheye:
    case CameraModelId::kSimpleRadialFisheye:
    case CameraModelId::kRadialFisheye: {
      // theta_d = theta (1 + k1 theta^2 + k2 theta^4 + ...), theta = atan(r).
      const T r = sqrt(r2);
      if (r < T(1e-12)) {
        *du = T(0);
        *dv = T(0);
        return;
      }
      const T theta = atan(r), t2 = theta * theta, t4 = t2 * t2;
      T poly = T(1);
      if (id == CameraModelId::kOpenCVFisheye) {
        poly += extra[0] * t2 + extra[1] * t4 + extra[2] * t4 * t2 + extra[3] * t4 * t4;
      } else if (id == CameraModelId::kSimpleRadialFisheye) {
        poly += extra[0] * t2;
      } else {
        poly += extra[0] * t2 + extra[1] * t4;
      }
      const T scale = theta * poly / r;
      *du = u * scale - u;
      *dv = v * scale - v;
      return;
    }
    default:
      // Unsupported models never reach here: FindCameraModel(...)->supported is checked first.
      *du = T(0);
      *dv = T(0);
      return;
  }
}

// Number of focal/principal-point parameters before the distortion ones: 3 for single-focal
// models (f, cx, cy), 4 otherwise.
int NumFocalParams(CameraModelId id);

// Projects a point in camera coordinates (z > 0) to pixels with the model's distortion.
template <typename T>
void ImgFromCam(CameraModelId id, const T* params, T x, T y, T z, T* px, T* py) {
  const int nf = NumFocalParams(id);
  const T fx = params[0], fy = nf == 3 ? params[0] : params[1];
  const T cx = params[nf - 2], cy = params[nf - 1];
  const T u = x / z, v = y / z;
  T du, dv;
  Distortion(id, params + nf, u, v, &du, &dv);
  *px = fx * (u + du) + cx;
  *py = fy * (v + dv) + cy;
}

}  // namespace perf::colmap
