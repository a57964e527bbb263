// Per-ray math of the reconstruction (DESIGN.md "One ray", "Derivatives"): on the march of
// ray_march.h, front-to-back compositing through the grid and the shells (paper eq. 3-4), the auxiliary residual (paper "Auxiliary terms") and the backward sweep of paper
// Algorithm 1. Host and device (PERF_HD), templated on the scalar: float on the GPU, double in
// tests. The backends add only launches, memory and reductions around these functions.
#pragma once

#include "recon_cuda/core/grid_sample.h"
#include "recon_cuda/core/ray_march.h"
#include "recon_cuda/core/ray_types.h"
#include "recon_cuda/core/shells.h"

namespace perf::recon {

// The spherical harmonics of one ray (ray_types.h ShParam): the basis at its direction (box
// frame) and where the coefficients are; degree 0: none.
template <class T>
struct RaySh {
  int degree = 0, bands = 0;
  int64_t start = 0;
  T y[kMaxShBands];
};

template <class T>
PERF_HD_INLINE RaySh<T> ShOfRay(const VolumeView<T>& vol, const BoxRay<T>& ray) {
  RaySh<T> sh;
  sh.degree = vol.sh_degree;
  if (sh.degree > 0) {
    sh.start = vol.ShStart();
    sh.bands = ShBasis(sh.degree, ray.dir, sh.y);
  }
  return sh;
}

// v[0..2] += sum_k y_k times band k of `params` (a parameter-sized vector) interpolated at gs.
template <class T>
PERF_HD_INLINE void AddShColour(const T* params, const RaySh<T>& sh, const GridSample<T>& gs, T* v) {
  const int stride = ShStride(sh.degree);
  for (int q = 0; q < 8; ++q) {
    if (gs.cell[q] < 0) continue;
    const T* p = params + sh.start + stride * gs.cell[q];
    for (int k = 0; k < sh.bands; ++k) {
      const T wy = gs.w[q] * sh.y[k];
      for (int c = 0; c < 3; ++c) v[c] += wy * p[3 * k + c];
    }
  }
}

// On the CPU, asks for the lines of a sample's cells' bands before its grid values are gathered,
// so that the two gathers' cache misses overlap; nothing on the device.
template <class T>
PERF_HD_INLINE void PrefetchShBands(const T* params, const RaySh<T>& sh, const GridSample<T>& gs) {
#if !defined(__CUDA_ARCH__)
  const int stride = ShStride(sh.degree);
  for (int q = 0; q < 8; ++q) {
    if (gs.cell[q] < 0) continue;
    const T* p = params + sh.start + stride * gs.cell[q];
    __builtin_prefetch(p);               // a block's first line
    __builtin_prefetch(p + stride - 1);  // and its last, where it crosses one
  }
#endif
}

// Shell lookups along one ray, innermost first; a missed shell is transparent (a = 0).
template <class T>
struct ShellStack {
  bool hit[kMaxShells];
  CubeCoord<T> coord[kMaxShells];
  T e[kMaxShells][3];
  T a[kMaxShells];  // the outermost is forced to 1
  T p[kMaxShells];  // P_k = prod_{m<k} (1 - a_m)
  T s[3];           // S = sum_k P_k a_k e_k
};

// Where the shells' lookups start along the ray: behind the box, or at the origin when it misses it.
template <class T>
PERF_HD_INLINE T ShellStart(const March<T>& march) {
  return march.hit ? march.t_max : T(0);
}

// Where the ray leaves shell k, from t_start on (ShellStart), as a cube-map coordinate; false
// when it misses the shell. EvalShells' lookup, and the compact record's recomputation of it.
template <class T>
PERF_HD_INLINE bool ShellCoordAt(const VolumeView<T>& vol, const BoxRay<T>& ray, T t_start, int k, CubeCoord<T>* c) {
  T t;
  if (!SphereExit(ray.origin, ray.dir, vol.shell_center, vol.shell_radii[k], t_start, &t)) return false;
  *c = DirectionToCube(ray.origin + ray.dir * t - vol.shell_center);
  return true;
}

// weights: when given, [num_shells] the texel weights of each shell hit (the compact record's
// J^T J p needs them too; Forward and Backward leave them out of their registers).
template <class T>
PERF_HD_INLINE void EvalShells(const VolumeView<T>& vol, const BoxRay<T>& ray, const March<T>& march,
                               ShellStack<T>* st, TexelSample<T>* weights = nullptr) {
  const T t_start = ShellStart(march);
  T p = 1;
  for (int c = 0; c < 3; ++c) st->s[c] = 0;
  for (int k = 0; k < vol.num_shells; ++k) {
    st->p[k] = p;
    st->hit[k] = ShellCoordAt(vol, ray, t_start, k, &st->coord[k]);
    if (!st->hit[k]) {
      st->a[k] = 0;
      for (int c = 0; c < 3; ++c) st->e[k][c] = 0;
      continue;
    }
    T v[4];
    const TexelSample<T> ts = TexelWeights(vol.GridParams(), vol.m, k, st->coord[k]);
    if (weights) weights[k] = ts;
    GatherTexels(vol.params, ts, v);
    st->a[k] = k == vol.num_shells - 1 ? T(1) : v[3];
    for (int c = 0; c < 3; ++c) {
      st->e[k][c] = v[c];
      st->s[c] += p * st->a[k] * v[c];
    }
    p *= 1 - st->a[k];
  }
}


// Pixel jitter: the hash's sample ids 0xfffffffe (x) and 0xffffffff (y) are reserved for it; the
// march uses ids 0 .. count-1, so the two never collide for any grid up to 2^32 samples a ray.
inline constexpr uint32_t kPixelJitterX = 0xfffffffeu;
inline constexpr uint32_t kPixelJitterY = 0xffffffffu;

// The ray of pixel (px, py) as every pass of one iteration sees it: jittered inside the pixel
// when jit.enabled and jit.pixel, through the pixel centre otherwise (rendering, and training by
// default: ResidualSettings::pixel_jitter says why).
template <class T>
PERF_HD_INLINE BoxRay<T> PixelBoxRay(const PinholeCamera<T>& cam, const BoxFrame<T>& box, int n, int px, int py,
                                     const Jitter& jit) {
  const bool move = jit.enabled && jit.pixel;
  const T jx = move ? Uniform01<T>(jit.seed, jit.ray, kPixelJitterX) : T(0.5);
  const T jy = move ? Uniform01<T>(jit.seed, jit.ray, kPixelJitterY) : T(0.5);
  Vec3<T> o, d;
  PixelRay(cam, px, py, jx, jy, &o, &d);
  return ToBoxRay(box, n, o, d);
}

// What the forward saw at one march sample, kept so that a backward sweep on the same thread
// need not gather the grid or call exp again (the CPU backend records; the GPU recomputes).
template <class T>
struct SampleRecord {
  GridSample<T> gs;  // the sample's cells and trilinear weights
  T t, delta;
  T v[4];   // (r, g, b, sigma) interpolated at t
  T trans;  // T_i, the transmittance in front of the sample
  T keep;   // exp(-sigma_i delta_i) = 1 - alpha_i
  int k;    // the sample's march index (its jitter's id)
};

template <class T>
struct RayOutput {
  T h[3];         // composited colour H
  T t_box;        // transmittance through the box only
  T depth;        // optical depth through the box, sum sigma_i delta_i
  T shells[3];    // S, the shells' colour before the box's transmittance
  T residual[4];  // gain H + offset - C (3; ColourTransform), then L (AuxResidual)
  T dl_dt;        // dL / dT_box
  int count;      // samples composited (the march may stop early, and skip empty bricks)
  int end;        // the march index after the last sample considered (Backward walks back from it)
};

// T in a non-deduced context (so that a nullptr record argument does not block deduction).
template <class T>
struct Identity {
  using type = T;
};

// The fourth residual L of a ray, a function of T_box only. Without a known alpha (alpha < 0):
// the paper's auxiliary term L = lambda (1 - 4 (T_box - 0.5)^2), which pushes every ray's box
// opacity to 0 or 1. With the photo's alpha at the pixel (alpha >= 0, RGBA photos): the box
// opacity should be that alpha, L = lambda ((1 - T_box) - alpha); this tells empty space from
// foreground where the colour cannot (white fog in front of a white background).
template <class T>
PERF_HD_INLINE void AuxResidual(T t_box, T lambda, T alpha, T* l, T* dl_dt) {
  if (alpha >= 0) {
    *l = lambda * ((1 - t_box) - alpha);
    *dl_dt = -lambda;
  } else {
    const T q = t_box - T(0.5);
    *l = lambda * (1 - 4 * q * q);
    *dl_dt = -8 * lambda * q;
  }
}

// A photo's colour transform (per-photo exposure): the photo shows gain_c H_c + offset_c
// of the composited colour H. The identity for photos whose exposure is not solved.
template <class T>
struct ColourTransform {
  T gain[3] = {1, 1, 1};
  T offset[3] = {0, 0, 0};
};

// Front to back (paper eq. 3-4): alpha_i = 1 - exp(-sigma_i delta_i), T_i = exp(-sum_{j<i}
// sigma_j delta_j), H = sum_i T_i alpha_i c_i + T_box S. target: the pixel colour C [3].
// stop: the march ends once T_i < stop (early ray termination; 0 marches the whole box). What is
// left behind then weighs less than `stop`, and the derivatives are those of the truncated sum.
// record: optional [MakeMarch(vol, ray).count] scratch that Backward can read instead of
// recomputing (the first `count` entries are written). alpha: the photo's alpha at the pixel, or < 0 when unknown (AuxResidual).
// xf: the photo's colour transform; the colour residuals are gain_c H_c + offset_c - C_c (h stays H).
template <class T>
PERF_HD RayOutput<T> Forward(const VolumeView<T>& vol, const BoxRay<T>& ray, const Jitter& jit, const T* target,
                             T lambda, T stop = T(0), typename Identity<SampleRecord<T>>::type* record = nullptr,
                             T alpha = T(-1), const ColourTransform<T>& xf = ColourTransform<T>{}) {
  RayOutput<T> out;
  const March<T> march = MakeMarch(vol, ray);
  const RaySh<T> sh = ShOfRay(vol, ray);
  T depth = 0, trans = 1;
  for (int c = 0; c < 3; ++c) out.h[c] = 0;
  int taken = 0;
  out.end = march.count;
  MarchStep<T> st{};
  for (int k = TakeSample(vol, ray, march, 0, 1, jit, &st); k < march.count;
       k = TakeSample(vol, ray, march, k + 1, 1, jit, &st)) {
    T v[4];
    const GridSample<T> gs = TrilinearWeights(vol.n, vol.brick_slot, ray.GridPoint(st.t));
    if (sh.degree > 0) PrefetchShBands(vol.params, sh, gs);
    GatherGrid(vol.params, gs, v);
    const T od = v[3] * st.delta;
    // A sample with no density adds nothing to h; its colour is needed only by Backward's
    // density partial, from the record.
    if (sh.degree > 0 && (record || od != T(0))) AddShColour(vol.params, sh, gs, v);
    const T keep = Exp(-od);
    const T weight = trans * (1 - keep);
    for (int c = 0; c < 3; ++c) out.h[c] += weight * v[c];
    if (record) record[taken] = {gs, st.t, st.delta, {v[0], v[1], v[2], v[3]}, trans, keep, k};
    ++taken;
    depth += od;
    trans *= keep;
    if (trans < stop) {
      out.end = k + 1;
      break;
    }
  }
  out.count = taken;
  out.depth = depth;
  out.t_box = Exp(-depth);
  ShellStack<T> shells;
  EvalShells(vol, ray, march, &shells);
  for (int c = 0; c < 3; ++c) {
    out.shells[c] = shells.s[c];
    out.h[c] += out.t_box * shells.s[c];
    out.residual[c] = xf.gain[c] * out.h[c] + xf.offset[c] - target[c];
  }
  AuxResidual(out.t_box, lambda, alpha, &out.residual[3], &out.dl_dt);
  return out;
}

// The partials of one march sample before they are spread over its 8 cells with the trilinear
// weights w: d r_c / d c_c = w dc (the same for the three channels; a sample's colour enters only
// its own channel's residual), d r_c / d sigma = w ds[c], d L / d sigma = w dl; with spherical
// harmonics, d r_c / d (band k of channel c) = w dc y_k (RaySh: y_k is the ray's).
template <class T>
struct SamplePartials {
  T dc;
  T ds[3];
  T dl;
};

// The partials of one shell hit before the bilinear weights w: d r_c / d e_c = w de,
// d r_c / d a = w da[c] (none when the shell is the opaque outermost one); L does not depend on
// the shells.
template <class T>
struct ShellPartials {
  T de;
  T da[3];
  bool opaque;
};

// dL/dsigma_i over delta_i, the same for every sample of a ray (see Backward's derivation): a
// sample's partial of the fourth residual is this times its delta.
template <class T>
PERF_HD_INLINE T DlPerDelta(const RayOutput<T>& fwd) {
  return -fwd.dl_dt * fwd.t_box;
}

// The partials of shell k, hit by a ray of box transmittance tb (Backward's derivation below),
// from the ray's shells (EvalShells) and the colour behind shell k, B_k, in `behind`, which
// becomes B_{k-1}: call it for the shells hit, outermost first, from behind = 0. Backward's, and
// the compact record's recomputation of them (cpu_jacobian_record.h RecordedShells).
template <class T>
PERF_HD_INLINE ShellPartials<T> ShellPartialsAt(const ShellStack<T>& shells, int k, int num_shells, T tb,
                                                T behind[3]) {
  const T* e = shells.e[k];
  const T a = shells.a[k];
  ShellPartials<T> sp;
  sp.de = tb * shells.p[k] * a;
  sp.opaque = k == num_shells - 1;
  for (int c = 0; c < 3; ++c) sp.da[c] = tb * shells.p[k] * (e[c] - behind[c]);
  for (int c = 0; c < 3; ++c) behind[c] = a * e[c] + (1 - a) * behind[c];
  return sp;
}

// Backward sweep (paper Algorithm 1). Calls
//   visit.Shell(k, const CubeCoord<T>&, const TexelSample<T>&, const ShellPartials<T>&)
//                                                                    for each shell hit, outermost first;
//   visit.Sample(k, const MarchStep<T>&, const GridSample<T>&, const SamplePartials<T>&)
//                                                                    for each sample, last first
//                                                                    (k: its march index).
// A parameter can be reached several times per ray (neighbouring samples share cells; border
// cells repeat within one sample); the row of J is the SUM of those contributions.
// record: what Forward recorded for this ray (same vol, ray and jit), or nullptr to recompute.
//
// Derivation. Let D_i = sum_{j<i} sigma_j delta_j, T_i = exp(-D_i), T_box = exp(-D_n),
// G_i = sum_{j>i} T_j alpha_j c_j + T_box S, the colour arriving from behind sample i.
//   dH/dc_i     = T_i alpha_i                                      (only c_i's own channel)
//   dH/dsigma_i = delta_i T_i (1 - alpha_i) c_i  [from T_i alpha_i c_i, d alpha_i = delta_i (1 - alpha_i)]
//               - delta_i G_i                    [every T_j, j > i, and T_box carry exp(-sigma_i delta_i)]
//   dT_box/dsigma_i = -delta_i T_box, so dL/dsigma_i = -dL/dT_box delta_i T_box (dL/dT_box from
//   Forward: -8 lambda (T_box - 0.5) for the paper's term, -lambda for the alpha residual).
// Algorithm 1 walks i = n-1..0 with V = D_n, V -= sigma_i delta_i giving D_i, and G starting at
// the shells' T_box S (not 0, DESIGN.md), G += T_i alpha_i c_i after sample i.
// Shells: S = sum_k P_k a_k e_k, P_k = prod_{m<k} (1 - a_m). With B_k = the shells' colour behind
// shell k as seen from just outside it, B_{K-1} = 0, B_{k-1} = a_k e_k + (1 - a_k) B_k:
//   S = sum_{j<k} P_j a_j e_j + P_k (a_k e_k + (1 - a_k) B_k), hence
//   dH/de_k = T_box P_k a_k,   dH/da_k = T_box P_k (e_k - B_k)
// (= T_box [P_k e_k - sum_{j>k} prod_{m<j, m!=k} (1 - a_m) a_j e_j]); the outermost a is fixed
// at 1, so its opacity texels get no partial. Shells do not enter T_box, so dL/d(texel) = 0.
// Values are linear in the parameters, so each partial is spread with the interpolation weights.
template <class T, class Visitor>
PERF_HD void Backward(const VolumeView<T>& vol, const BoxRay<T>& ray, const Jitter& jit,
                      const RayOutput<T>& fwd, Visitor& visit, const SampleRecord<T>* record = nullptr) {
  const March<T> march = MakeMarch(vol, ray);
  const RaySh<T> sh = ShOfRay(vol, ray);
  const T tb = fwd.t_box;
  ShellStack<T> shells;
  EvalShells(vol, ray, march, &shells);
  T behind[3] = {0, 0, 0};  // B_k
  for (int k = vol.num_shells - 1; k >= 0; --k) {
    if (!shells.hit[k]) continue;  // transparent: B passes through unchanged
    const ShellPartials<T> sp = ShellPartialsAt(shells, k, vol.num_shells, tb, behind);
    visit.Shell(k, shells.coord[k], TexelWeights(vol.GridParams(), vol.m, k, shells.coord[k]), sp);
  }

  T g[3];
  for (int c = 0; c < 3; ++c) g[c] = tb * fwd.shells[c];
  const T dl_per_delta = DlPerDelta(fwd);
  T v_depth = fwd.depth;
  MarchStep<T> st{};
  for (int k = record ? fwd.count - 1 : TakeSample(vol, ray, march, fwd.end - 1, -1, jit, &st); k >= 0;
       k = record ? k - 1 : TakeSample(vol, ray, march, k - 1, -1, jit, &st)) {
    T v[4], ti, keep;
    GridSample<T> gs;
    if (record) {
      const SampleRecord<T>& r = record[k];
      st = {r.t, r.delta};
      for (int ch = 0; ch < 4; ++ch) v[ch] = r.v[ch];
      gs = r.gs;
      ti = r.trans;
      keep = r.keep;
    } else {
      gs = TrilinearWeights(vol.n, vol.brick_slot, ray.GridPoint(st.t));
      if (sh.degree > 0) PrefetchShBands(vol.params, sh, gs);
      GatherGrid(vol.params, gs, v);
      if (sh.degree > 0) AddShColour(vol.params, sh, gs, v);
      const T od = v[3] * st.delta;
      v_depth -= od;
      ti = Exp(-v_depth);
      keep = Exp(-od);
    }
    SamplePartials<T> sp;
    sp.dc = ti * (1 - keep);
    for (int c = 0; c < 3; ++c) sp.ds[c] = st.delta * (ti * keep * v[c] - g[c]);
    sp.dl = dl_per_delta * st.delta;
    visit.Sample(record ? record[k].k : k, st, gs, sp);
    for (int c = 0; c < 3; ++c) g[c] += sp.dc * v[c];
  }
}

}  // namespace perf::recon
