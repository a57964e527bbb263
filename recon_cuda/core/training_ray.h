// The per-ray pieces both backends must read identically (DESIGN.md "One ray"): training ray i of
// a level as every pass of one iteration sees it, its targets, its cost, and a rendered pixel
// under the render rule. The ray set's colour type is a parameter: float on the CPU (RaySet),
// 8-bit on the GPU (cuda_kernels.h).
#pragma once

#include <stdint.h>

#include "recon_cuda/core/hd.h"
#include "recon_cuda/core/pose.h"

namespace perf::recon {

PERF_HD_INLINE float ColourValue(float v) { return v; }
PERF_HD_INLINE float ColourValue(uint8_t v) { return static_cast<float>(v) / 255.f; }

// A level's training rays, flat (training_data.h RaySet, or its device copy).
template <class Colour>
struct TrainingRays {
  const PinholeCamera<float>* cameras;  // [num_cameras]
  const RayPixel* pixels;               // [count]
  const Colour* colours;                // [count, 3]
  const Colour* alphas;                 // [count], or nullptr: no alpha residual (backend.h UsesAlpha)
  int64_t count;
  // Ray 0's index among the rays of every rank (RaySet::first_index): ray i's jitter is the one
  // ray first_index + i gets in a single process.
  int64_t first_index;
  // Each camera's exposure slot (ray_types.h ExposureParam), or nullptr: no exposure is solved.
  const int32_t* exposure_slot;
  // Each camera's pose slot (ray_types.h PoseParam; the same numbering), or nullptr: no pose is
  // refined.
  const int32_t* pose_slot = nullptr;
};

struct TrainingRay {
  BoxRay<float> ray;
  Jitter jit;
  int64_t pose;  // where its photo's pose values are in params (-1: not refined)
  Vec3<float> forward;  // its photo's imported optical axis in the box frame (pose.h BoxForward), with a pose
};

// Ray i in the iteration of `seed`: every pass of the iteration sees the same ray and jitter,
// through its photo's corrected pose at vol.params when poses are refined (pose.h ApplyPose).
template <class Colour>
PERF_HD_INLINE TrainingRay RayOf(const TrainingRays<Colour>& rays, const VolumeView<float>& vol,
                                 const BoxFrame<float>& box, int64_t i, uint32_t seed, bool jitter, bool pixel_jitter) {
  const RayPixel px = rays.pixels[i];
  const Jitter jit{seed, static_cast<uint32_t>(rays.first_index + i), jitter, pixel_jitter};
  TrainingRay tr{PixelBoxRay(rays.cameras[px.camera], box, vol.n, px.x, px.y, jit), jit, -1, {}};
  if (rays.pose_slot) {
    tr.pose = PoseParamOfSlot(vol, rays.pose_slot[px.camera]);
    if (tr.pose >= 0) {
      tr.forward = BoxForward(rays.cameras[px.camera], box);
      ApplyPose(vol, vol.params + tr.pose, tr.forward, &tr.ray);
    }
  }
  return tr;
}

template <class Colour>
PERF_HD_INLINE void TargetOf(const TrainingRays<Colour>& rays, int64_t i, float target[3]) {
  for (int c = 0; c < 3; ++c) target[c] = ColourValue(rays.colours[3 * i + c]);
}

// The alpha target of ray i (AuxResidual), or -1: the paper's auxiliary term.
template <class Colour>
PERF_HD_INLINE float AlphaOf(const TrainingRays<Colour>& rays, int64_t i) {
  return rays.alphas ? ColourValue(rays.alphas[i]) : -1.f;
}

// The exposure slot of ray i's photo, or -1 (not solved).
template <class Colour>
PERF_HD_INLINE int ExposureSlotOf(const TrainingRays<Colour>& rays, int64_t i) {
  return rays.exposure_slot ? rays.exposure_slot[rays.pixels[i].camera] : -1;
}

// The transform that parameters `params` give the photo of exposure slot `slot` (< 0: identity).
template <class T>
PERF_HD_INLINE ColourTransform<T> TransformOf(const T* params, int64_t exposure_start, int slot) {
  ColourTransform<T> xf;
  if (slot < 0) return xf;
  const T* e = params + ExposureParam(exposure_start, slot);
  for (int c = 0; c < 3; ++c) {
    xf.gain[c] = 1 + e[c];
    xf.offset[c] = e[4 + c];
  }
  return xf;
}

// Ray i's photo's transform at vol's parameters.
template <class Colour>
PERF_HD_INLINE ColourTransform<float> TransformOfRay(const TrainingRays<Colour>& rays, const VolumeView<float>& vol,
                                                    int64_t i) {
  return TransformOf(vol.params, vol.ExposureStart(), ExposureSlotOf(rays, i));
}

// A ray's share of the cost, in double from the float residuals: 0.5 (rho(|r_colour|^2) + L^2),
// rho the robust loss of ResidualSettings::robust_scale c (Cauchy, c^2 log(1 + q / c^2); c <= 0:
// least squares, q), and the colour part's squared error (for PSNR).
struct RayCost {
  double cost, colour_sse;
};
PERF_HD_INLINE RayCost CostOf(const RayOutput<float>& o, float robust_scale = 0.f) {
  double sse = 0;
  for (int c = 0; c < 3; ++c) sse += static_cast<double>(o.residual[c]) * o.residual[c];
  const double c2 = static_cast<double>(robust_scale) * robust_scale;
  const double colour = robust_scale > 0 ? c2 * log1p(sse / c2) : sse;
  return {0.5 * (colour + static_cast<double>(o.residual[3]) * o.residual[3]), sse};
}

// A rendered pixel under the render rule (render_rule.h): where the box's opacity along the ray
// is below min_box_opacity the box is treated as empty and the pixel shows the shells.
PERF_HD_INLINE void RulePixel(const RayOutput<float>& o, float min_box_opacity, float colour[3], float* opacity) {
  const float a = 1 - o.t_box;
  const bool empty = a < min_box_opacity;
  for (int c = 0; c < 3; ++c) colour[c] = empty ? o.shells[c] : o.h[c];
  *opacity = a;
}

}  // namespace perf::recon
