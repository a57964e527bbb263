// Element-wise rules of the parameter vector, host and device: which kind a parameter is, its
// valid range (the projection of DESIGN.md "Gauss-Newton step") and one Adam update, so that the
// CPU loops and the CUDA vector kernels apply the very same formulas.
#pragma once

#include <stdint.h>

#include "recon_cuda/core/ray_types.h"

namespace perf::recon {

// What parameter i is (for per-kind learning rates, bounds and the smoothness weights).
enum class ParamKind {
  kGridColour,
  kGridDensity,
  kShellColour,
  kShellOpacity,
  kExposureGain,
  kExposureOffset,
  kGridSh,
  kPoseRotation,
  kPoseCentre,
  kPoseFocal
};
inline constexpr int kParamKinds = 10;

// Where each part of the parameter vector starts (layout in ray_types.h; VolumeShape::Layout).
struct ParamLayout {
  int64_t grid_params = 0;     // the shells' texels (GridParamCount(n), or the sparse grid's)
  int64_t sh_start = 0;        // the grid's spherical harmonics (== exposure_start without them)
  int64_t exposure_start = 0;  // the photos' exposures (== pose_start without them)
  int64_t pose_start = 0;      // the photos' pose corrections (== the parameter count without them)
};

// What parameter i is. Padding zeros count with their group (they never move).
PERF_HD_INLINE ParamKind KindOfParam(const ParamLayout& l, int64_t i) {
  if (i >= l.pose_start) {
    const int64_t v = (i - l.pose_start) % kPoseValues;
    return v < 3 ? ParamKind::kPoseRotation : v == 3 ? ParamKind::kPoseFocal : ParamKind::kPoseCentre;
  }
  if (i >= l.exposure_start) {
    return (i - l.exposure_start) % kExposureValues < 4 ? ParamKind::kExposureGain : ParamKind::kExposureOffset;
  }
  if (i >= l.sh_start) return ParamKind::kGridSh;
  const int64_t grid_params = l.grid_params;
  const bool fourth = i % 4 == 3;
  return i < grid_params ? (fourth ? ParamKind::kGridDensity : ParamKind::kGridColour)
                         : (fourth ? ParamKind::kShellOpacity : ParamKind::kShellColour);
}

// The valid range of a kind: sigma >= 0, colours and opacities in [0, 1], a photo's gain 1 + gamma
// in [0.5, 2] and its offset in [-0.5, 0.5] (wider would mean a badly exposed or wrong photo), a
// spherical-harmonic coefficient in [-1, 1] (a band then moves the colour by up to 0.49 or 1.09),
// a pose's rotation within 0.1 rad (5.7 degrees) per axis, its centre within a quarter of the
// box's shortest side per axis and its focal length's log scale within 0.1 (10.5 %) (larger
// corrections mean a wrong registration or calibration, not a refinement).
inline constexpr float kMaxPoseRotation = 0.1f;
inline constexpr float kMaxPoseCentre = 0.25f;
inline constexpr float kMaxPoseFocal = 0.1f;
PERF_HD_INLINE float LowerBound(ParamKind kind) {
  return kind == ParamKind::kExposureGain || kind == ParamKind::kExposureOffset ? -0.5f
         : kind == ParamKind::kGridSh                                            ? -1.f
         : kind == ParamKind::kPoseRotation                                      ? -kMaxPoseRotation
         : kind == ParamKind::kPoseCentre                                        ? -kMaxPoseCentre
         : kind == ParamKind::kPoseFocal                                         ? -kMaxPoseFocal
                                                                                 : 0.f;
}
PERF_HD_INLINE float UpperBound(ParamKind kind) {
  return kind == ParamKind::kGridDensity ? 3.0e38f
         : kind == ParamKind::kExposureGain ? 1.f
         : kind == ParamKind::kExposureOffset ? 0.5f
         : kind == ParamKind::kPoseRotation ? kMaxPoseRotation
         : kind == ParamKind::kPoseCentre ? kMaxPoseCentre
         : kind == ParamKind::kPoseFocal ? kMaxPoseFocal
                                          : 1.f;
}
PERF_HD_INLINE float ProjectToValid(ParamKind kind, float v) { return Clamp(v, LowerBound(kind), UpperBound(kind)); }

// The kinds a level holds whatever their gradient: the shells (a known background), the photos'
// pose corrections (a level that does not refine them), everything but the poses (a pose fit
// against a frozen volume), the photos' focal lengths (not refined: --refine-intrinsics off).
struct HeldKinds {
  bool shells = false, poses = false, volume = false, focal = false;
};
PERF_HD_INLINE bool IsPose(ParamKind kind) {
  return kind == ParamKind::kPoseRotation || kind == ParamKind::kPoseCentre || kind == ParamKind::kPoseFocal;
}

// Whether parameter x (gradient g, kind `kind`) is held for one iteration, given the kinds the
// level holds and whether bounds are active: the active set of a
// projected Gauss-Newton method (Bertsekas, "Projected Newton methods for optimization
// problems with simple constraints", 1982). A parameter at a bound of its valid range whose
// gradient points out of the range would only be moved out by a descent step and projected
// back; leaving it in the system lets CG spend the step on that move and shape every other
// parameter's step around it. Held parameters are left out of that iteration's system.
PERF_HD_INLINE bool HeldParameter(ParamKind kind, float x, float g, const HeldKinds& held, bool bounds) {
  if (held.shells && (kind == ParamKind::kShellColour || kind == ParamKind::kShellOpacity)) return true;
  if (IsPose(kind) ? held.poses : held.volume) return true;
  if (held.focal && kind == ParamKind::kPoseFocal) return true;
  if (!bounds) return false;
  if (x <= LowerBound(kind) && g > 0) return true;
  return x >= UpperBound(kind) && g < 0;
}

// One Adam step (Kingma & Ba) in scalars: the host computes the bias corrections once per step.
struct AdamCoefficients {
  float lr_colour, lr_density, lr_opacity;  // grid and shell colours share lr_colour
  float beta1, beta2, epsilon;
  float c1, c2;  // 1 / (1 - beta^t), t = step number from 1
};

// m, v: the moments; x moves against the bias-corrected m / sqrt(v) (projection separate).
PERF_HD_INLINE void AdamUpdate(const AdamCoefficients& a, ParamKind kind, float g, float* x, float* m, float* v) {
  *m = a.beta1 * *m + (1 - a.beta1) * g;
  *v = a.beta2 * *v + (1 - a.beta2) * g * g;
  // Adam does not refine poses (--refine-poses is a Gauss-Newton option): their rate is 0.
  const float lr = IsPose(kind)                                ? 0.f
                   : kind == ParamKind::kGridDensity  ? a.lr_density
                   : kind == ParamKind::kShellOpacity ? a.lr_opacity
                                                       : a.lr_colour;
  *x -= lr * (*m * a.c1) / (Sqrt(*v * a.c2) + a.epsilon);
}

}  // namespace perf::recon
