// Element-wise rules of the parameter vector, host and device: which kind a parameter is, its
// valid range (the projection of DESIGN.md "Gauss-Newton step") and one Adam update, so that the
// CPU loops and the CUDA vector kernels apply the very same formulas.
#pragma once

#include <stdint.h>

#include "recon_cuda/ray_types.h"

namespace perf::recon {

// Which of the 4 channels of parameter i is what (for per-kind learning rates and bounds).
enum class ParamKind { kGridColour, kGridDensity, kShellColour, kShellOpacity };

// grid_params: GridParamCount(n), where the shells' texels start (layout in ray_types.h).
PERF_HD_INLINE ParamKind KindOfParam(int64_t grid_params, int64_t i) {
  const bool fourth = i % 4 == 3;
  return i < grid_params ? (fourth ? ParamKind::kGridDensity : ParamKind::kGridColour)
                         : (fourth ? ParamKind::kShellOpacity : ParamKind::kShellColour);
}

// The valid range of one parameter: sigma >= 0, colours and opacities in [0, 1].
PERF_HD_INLINE float ProjectToValid(ParamKind kind, float v) {
  return kind == ParamKind::kGridDensity ? Max(v, 0.f) : Clamp(v, 0.f, 1.f);
}

// Whether parameter x (gradient g, kind `kind`) is held for one iteration, given whether the
// shells are fixed (a known background) and whether bounds are active: the active set of a
// projected Gauss-Newton method (Bertsekas, "Projected Newton methods for optimization
// problems with simple constraints", 1982). A parameter at a bound of its valid range whose
// gradient points out of the range would only be moved out by a descent step and projected
// back; leaving it in the system lets CG spend the step on that move and shape every other
// parameter's step around it. Held parameters are left out of that iteration's system.
PERF_HD_INLINE bool HeldParameter(ParamKind kind, float x, float g, bool fixed_shells, bool bounds) {
  if (fixed_shells && (kind == ParamKind::kShellColour || kind == ParamKind::kShellOpacity)) return true;
  if (!bounds) return false;
  if (x <= 0 && g > 0) return true;
  return kind != ParamKind::kGridDensity && x >= 1 && g < 0;
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
  const float lr = kind == ParamKind::kGridDensity ? a.lr_density
                   : kind == ParamKind::kShellOpacity ? a.lr_opacity
                                                       : a.lr_colour;
  *x -= lr * (*m * a.c1) / (Sqrt(*v * a.c2) + a.epsilon);
}

}  // namespace perf::recon
