#include "sfm_import/camera_models.h"

#include <array>

namespace perf::colmap {
namespace {

constexpr std::array<CameraModelInfo, 12> kModels = {{
    {CameraModelId::kSimplePinhole, "SIMPLE_PINHOLE", 3, true, "f, cx, cy"},
    {CameraModelId::kPinhole, "PINHOLE", 4, true, "fx, fy, cx, cy"},
    {CameraModelId::kSimpleRadial, "SIMPLE_RADIAL", 4, true, "f, cx, cy, k"},
    {CameraModelId::kRadial, "RADIAL", 5, true, "f, cx, cy, k1, k2"},
    {CameraModelId::kOpenCV, "OPENCV", 8, true, "fx, fy, cx, cy, k1, k2, p1, p2"},
    {CameraModelId::kOpenCVFisheye, "OPENCV_FISHEYE", 8, true, "fx, fy, cx, cy, k1, k2, k3, k4"},
    {CameraModelId::kFullOpenCV, "FULL_OPENCV", 12, true,
     "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6"},
    {CameraModelId::kFOV, "FOV", 5, false, "fx, fy, cx, cy, omega"},
    {CameraModelId::kSimpleRadialFisheye, "SIMPLE_RADIAL_FISHEYE", 4, true, "f, cx, cy, k"},
    {CameraModelId::kRadialFisheye, "RADIAL_FISHEYE", 5, true, "f, cx, cy, k1, k2"},
    {CameraModelId::kThinPrismFisheye, "THIN_PRISM_FISHEYE", 12, false,
     "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1"},
    {CameraModelId::kRadTanThinPrismFisheye, "RAD_TAN_THIN_PRISM_FISHEYE", 16, false,
     "fx, fy, cx, cy, k0, k1, k2, k3, k4, k5, p0, p1, s0, s1, s2, s3"},
}};

}  // namespace

const CameraModelInfo* FindCameraModel(int id) {
  for (const auto& m : kModels) {
    if (static_cast<int>(m.id) == id) return &m;
  }
  return nullptr;
}

const CameraModelInfo* FindCameraModel(std::string_view name) {
  for (const auto& m : kModels) {
    if (m.name == name) return &m;
  }
  return nullptr;
}

int NumFocalParams(CameraModelId id) {
  switch (id) {
    case CameraModelId::kSimplePinhole:
    case CameraModelId::kSimpleRadial:
    case CameraModelId::kRadial:
    case CameraModelId::kSimpleRadialFisheye:
    case CameraModelId::kRadialFisheye:
      return 3;
    default:
      return 4;
  }
}

FocalAndCentre GetFocalAndCentre(CameraModelId id, const double* params) {
  if (NumFocalParams(id) == 3) return {params[0], params[0], params[1], params[2]};
  return {params[0], params[1], params[2], params[3]};
}

}  // namespace perf::colmap
