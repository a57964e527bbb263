// Tests only: Backward's partials one parameter at a time, for dense Jacobians and central
// differences (the backends use their own visitors: cpu_backend.cc, cuda_passes.cu).
#pragma once

#include "recon_cuda/core/ray_math.h"

namespace perf::recon {

// Adapts a per-parameter callable f(index, dr_r, dr_g, dr_b, dL) to Backward's visitor: each
// call is one contribution to row entries J[r_c][index] (sum the calls for the row).
template <class T, class F>
struct PerParamVisitor {
  F& f;
  RaySh<T> sh{};  // the ray's spherical harmonics (degree 0: none)
  PERF_HD_INLINE void Shell(int, const CubeCoord<T>&, const TexelSample<T>& ts, const ShellPartials<T>& p) {
    for (int q = 0; q < 4; ++q) {
      const T w = ts.w[q];
      f(ts.param[q] + 0, p.de * w, T(0), T(0), T(0));
      f(ts.param[q] + 1, T(0), p.de * w, T(0), T(0));
      f(ts.param[q] + 2, T(0), T(0), p.de * w, T(0));
      if (!p.opaque) f(ts.param[q] + 3, p.da[0] * w, p.da[1] * w, p.da[2] * w, T(0));
    }
  }
  PERF_HD_INLINE void Sample(int, const MarchStep<T>&, const GridSample<T>& gs, const SamplePartials<T>& p) {
    for (int q = 0; q < 8; ++q) {
      if (gs.cell[q] < 0) continue;  // an inactive brick's cell
      const T w = gs.w[q];
      const int64_t base = GridParam(gs.cell[q], 0);
      f(base + 0, p.dc * w, T(0), T(0), T(0));
      f(base + 1, T(0), p.dc * w, T(0), T(0));
      f(base + 2, T(0), T(0), p.dc * w, T(0));
      f(base + 3, p.ds[0] * w, p.ds[1] * w, p.ds[2] * w, p.dl * w);
      for (int k = 0; k < sh.bands; ++k) {  // band k's channel c enters r_c as the colour does, times y_k
        const T e = p.dc * w * sh.y[k];
        f(ShParam(sh.start, sh.degree, gs.cell[q], k, 0), e, T(0), T(0), T(0));
        f(ShParam(sh.start, sh.degree, gs.cell[q], k, 1), T(0), e, T(0), T(0));
        f(ShParam(sh.start, sh.degree, gs.cell[q], k, 2), T(0), T(0), e, T(0));
      }
    }
  }
};

template <class T, class F>
PERF_HD_INLINE void BackwardPerParam(const VolumeView<T>& vol, const BoxRay<T>& ray, const Jitter& jit,
                                     const RayOutput<T>& fwd, F& f) {
  PerParamVisitor<T, F> v{f, ShOfRay(vol, ray)};
  Backward(vol, ray, jit, fwd, v);
}

}  // namespace perf::recon
