// Environment shells (DESIGN.md "Representation", "One ray" step 4): concentric spheres around
// the shell centre, each a cube map of 6 faces x M x M texels holding (r, g, b, a), bilinear
// within a face and clamped at the face border (faces are not stitched: lookups are continuous
// inside a face and jump by at most one texel's variation across a face edge).
#pragma once

#include "recon_cuda/core/ray_types.h"

namespace perf::recon {

// The crossing of the sphere |p - c| = r by p = o + t d (d unit) with the largest t, if that t is
// beyond t_start (the box exit, or 0 when the ray misses the box). That root is where the ray
// leaves the sphere, so a camera inside or outside the sphere sees each shell once.
template <class T>
PERF_HD_INLINE bool SphereExit(Vec3<T> o, Vec3<T> d, Vec3<T> c, T r, T t_start, T* t) {
  const Vec3<T> oc = o - c;
  const T b = Dot(oc, d);
  const T disc = b * b - (Dot(oc, oc) - r * r);
  if (disc < 0) return false;
  *t = -b + Sqrt(disc);
  return *t > t_start;
}

// Cube-map faces: 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z (the OpenGL convention for (u, v)), axes
// of the box frame. u, v in [0, 1], texel (iu, iv) covers [iu, iu + 1) / M x [iv, iv + 1) / M.
template <class T>
struct CubeCoord {
  int face;
  T u, v;
};

template <class T>
PERF_HD_INLINE CubeCoord<T> DirectionToCube(Vec3<T> d) {
  const T ax = Abs(d.x), ay = Abs(d.y), az = Abs(d.z);
  int face;
  T sc, tc, ma;
  if (ax >= ay && ax >= az) {
    face = d.x >= 0 ? 0 : 1;
    ma = ax;
    sc = d.x >= 0 ? -d.z : d.z;
    tc = -d.y;
  } else if (ay >= az) {
    face = d.y >= 0 ? 2 : 3;
    ma = ay;
    sc = d.x;
    tc = d.y >= 0 ? d.z : -d.z;
  } else {
    face = d.z >= 0 ? 4 : 5;
    ma = az;
    sc = d.z >= 0 ? d.x : -d.x;
    tc = -d.y;
  }
  return {face, (sc / ma + 1) * T(0.5), (tc / ma + 1) * T(0.5)};
}

// Inverse of DirectionToCube up to scale (a direction on the unit cube).
template <class T>
PERF_HD_INLINE Vec3<T> CubeToDirection(CubeCoord<T> c) {
  const T s = 2 * c.u - 1, t = 2 * c.v - 1;
  switch (c.face) {
    case 0: return {T(1), -t, -s};
    case 1: return {T(-1), -t, s};
    case 2: return {s, T(1), t};
    case 3: return {s, T(-1), -t};
    case 4: return {s, -t, T(1)};
    default: return {-s, -t, T(-1)};
  }
}

template <class T>
struct TexelSample {
  int64_t param[4];  // parameter index of each texel's channel 0 (see ShellParam)
  T w[4];            // bilinear weights, sum to 1
};

// grid_params: where the shells start in x (ShellParamAt).
template <class T>
PERF_HD_INLINE TexelSample<T> TexelWeights(int64_t grid_params, int m, int shell, CubeCoord<T> c) {
  int ulo, uhi, vlo, vhi;
  T fu, fv;
  LinearCoord(c.u * T(m), m, &ulo, &uhi, &fu);
  LinearCoord(c.v * T(m), m, &vlo, &vhi, &fv);
  TexelSample<T> s;
  for (int k = 0; k < 4; ++k) {
    const int du = k & 1, dv = k >> 1;
    s.param[k] = ShellParamAt(grid_params, m, shell, c.face, du ? uhi : ulo, dv ? vhi : vlo, 0);
    s.w[k] = (du ? fu : 1 - fu) * (dv ? fv : 1 - fv);
  }
  return s;
}

// params: the whole x; out: (r, g, b, a).
template <class T>
PERF_HD_INLINE void GatherTexels(const T* params, const TexelSample<T>& s, T out[4]) {
  for (int ch = 0; ch < 4; ++ch) out[ch] = 0;
  for (int k = 0; k < 4; ++k) {
    for (int ch = 0; ch < 4; ++ch) out[ch] += s.w[k] * params[s.param[k] + ch];
  }
}

}  // namespace perf::recon
