// The geometry of one ray (DESIGN.md "One ray"): the pinhole ray through a pixel, the volume it
// reads (VolumeView), the box slab test, and the jittered march through the grid with the
// brick-sparse grid's skips. Host and device (PERF_HD), templated on the scalar like ray_math.h.
#pragma once

#include "recon_cuda/core/grid_sample.h"
#include "recon_cuda/core/ray_types.h"

namespace perf::recon {

inline constexpr int kMaxShells = 8;  // callers check num_shells <= kMaxShells before launching

// Pinhole after undistortion (scene.h conventions): camera x right, y down, z forward; pixel px
// covers [px, px + 1), so the upper-left pixel's centre is (0.5, 0.5).
template <class T>
struct PinholeCamera {
  T fx, fy, cx, cy;
  T world_from_cam[12];  // row-major 3x4 [R | t], camera centre = t
};

// One training ray: pixel (x, y) of camera `camera` (an index into the level's cameras).
struct RayPixel {
  uint32_t camera;
  uint16_t x, y;
};

// The box of scene.h: world p is box-local q = R^T (p - center), inside when |q| <= size / 2.
template <class T>
struct BoxFrame {
  Vec3<T> center;
  Mat3<T> world_from_box;  // R
  Vec3<T> size;            // world units along the box axes
};

// Everything the ray math reads; trivially copyable (kernels take it by value).
template <class T>
struct VolumeView {
  const T* params;  // grid [n^3, 4] (or its active bricks) then shells [K, 6, m, m, 4]
  int n;            // grid cells per axis
  Vec3<T> size;     // box size, world units (same as BoxFrame::size)
  int num_shells;   // K <= kMaxShells; the outermost (K - 1) is opaque
  int m;            // texels per face side
  Vec3<T> shell_center;            // box-local frame: R^T (shells.center - box.center)
  T shell_radii[kMaxShells];       // world units, increasing
  // A brick-sparse grid (ray_types.h): its brick table [(n/8)^3] and stored bricks. nullptr:
  // the grid is dense.
  const int32_t* brick_slot = nullptr;
  const uint8_t* skip_blocks = nullptr;  // with brick_slot: the march's empty-space table (SkipBlockOf)
  int64_t active_bricks = 0;
  int sh_degree = 0;  // spherical harmonics of the grid's colour (ray_types.h ShParam); 0: none
  int exposures = 0;  // photos whose exposures follow the spherical harmonics (ExposureParam)
  int poses = 0;      // photos whose pose corrections follow the exposures (PoseParam); 0: none

  // Where the shells start in params.
  PERF_HD_INLINE int64_t GridParams() const {
    return brick_slot ? SparseGridParams(active_bricks) : GridParamCount(n);
  }
  // Where the grid's spherical harmonics start in params (ray_types.h ShParam).
  PERF_HD_INLINE int64_t ShStart() const { return GridParams() + 4 * static_cast<int64_t>(num_shells) * 6 * m * m; }
  // Where the photos' exposures start in params (ray_types.h ExposureParam).
  PERF_HD_INLINE int64_t ExposureStart() const {
    return ShStart() + (sh_degree > 0 ? ShStride(sh_degree) * (GridParams() / 4) : 0);
  }
  // Where the photos' pose corrections start in params (ray_types.h PoseParam).
  PERF_HD_INLINE int64_t PoseStart() const { return ExposureStart() + static_cast<int64_t>(kExposureValues) * exposures; }
  // World units per unit of a pose's centre offset: the box's shortest side.
  PERF_HD_INLINE T PoseScale() const { return Min(size.x, Min(size.y, size.z)); }
};

// A ray in two coordinate systems sharing one parameter t, which is world distance from the
// camera centre (the world direction is unit length and both maps are affine):
//   box-local metric: q(t) = origin + t dir, q = R^T (p - center);
//   grid units:       g(t) = grid_origin + t grid_dir, g = (q + size / 2) * n / size per axis,
//                     so the box is [0, n]^3 and cell (i, j, k) spans [i, i+1) x [j, j+1) x ...
template <class T>
struct BoxRay {
  Vec3<T> origin, dir;
  Vec3<T> grid_origin, grid_dir;
  PERF_HD_INLINE Vec3<T> GridPoint(T t) const { return grid_origin + grid_dir * t; }
};

// World ray through pixel (px, py) at jitter (jx, jy) in [0, 1)^2: x = px + jx, y = py + jy,
// camera direction ((x - cx) / fx, (y - cy) / fy, 1), rotated to world and normalised.
template <class T>
PERF_HD_INLINE void PixelRay(const PinholeCamera<T>& cam, int px, int py, T jx, T jy, Vec3<T>* origin,
                             Vec3<T>* dir) {
  const Vec3<T> dc{(T(px) + jx - cam.cx) / cam.fx, (T(py) + jy - cam.cy) / cam.fy, T(1)};
  const T* m = cam.world_from_cam;
  *origin = {m[3], m[7], m[11]};
  *dir = Normalized(Vec3<T>{m[0] * dc.x + m[1] * dc.y + m[2] * dc.z, m[4] * dc.x + m[5] * dc.y + m[6] * dc.z,
                            m[8] * dc.x + m[9] * dc.y + m[10] * dc.z});
}

// Sets the ray's grid-unit copy from its box-local origin and direction (box size `size`).
template <class T>
PERF_HD_INLINE void SetGridRay(Vec3<T> size, int n, BoxRay<T>* r) {
  const Vec3<T> scale = Div(Vec3<T>{T(n), T(n), T(n)}, size);
  r->grid_origin = Mul(r->origin + size * T(0.5), scale);
  r->grid_dir = Mul(r->dir, scale);
}

template <class T>
PERF_HD_INLINE BoxRay<T> ToBoxRay(const BoxFrame<T>& box, int n, Vec3<T> world_origin, Vec3<T> world_dir) {
  BoxRay<T> r;
  r.origin = MulMatTransposed(box.world_from_box, world_origin - box.center);
  r.dir = MulMatTransposed(box.world_from_box, Normalized(world_dir));
  SetGridRay(box.size, n, &r);
  return r;
}

template <class T>
struct SlabHit {
  T t_min, t_max;
  bool hit;
};

// Ray o + t d against [0, n]^3, t >= 0 (a ray starting inside enters at t = 0). A zero direction
// component constrains nothing when the origin is within that slab and misses otherwise, with
// no division by zero (no reliance on IEEE infinities, which fast-math kernels may not keep).
template <class T>
PERF_HD_INLINE SlabHit<T> SlabTest(Vec3<T> o, Vec3<T> d, T n) {
  T t0 = 0, t1 = T(3.0e38);  // below float's max
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) {
      if (o[a] < 0 || o[a] > n) return {0, 0, false};
      continue;
    }
    T ta = (0 - o[a]) / d[a], tb = (n - o[a]) / d[a];
    if (ta > tb) {
      const T s = ta;
      ta = tb;
      tb = s;
    }
    t0 = Max(t0, ta);
    t1 = Min(t1, tb);
  }
  return {t0, t1, t1 > t0};
}

// The march: segments of length delta (the shortest cell side, world distance) from t_min; the
// last is cut at t_max. Sample k lies in segment k at start + u_k * length, u_k uniform in
// [0, 1): i.e. t = t_min + (k + 0.5 + (u_k - 0.5)) delta, within half a step of its regular
// position. Its delta_k is the segment length, so sum delta_k = t_max - t_min exactly.
template <class T>
struct March {
  T t_min, t_max, delta;
  int count;
  bool hit;
};
template <class T>
struct MarchStep {
  T t, delta;
};
struct Jitter {
  uint32_t seed, ray;
  bool enabled;  // false: u_k = 0.5 (rendering)
  bool pixel;    // with enabled: the ray also moves inside its pixel (false: through the centre)
};

template <class T>
PERF_HD_INLINE March<T> MakeMarch(const VolumeView<T>& vol, const BoxRay<T>& ray) {
  const SlabHit<T> s = SlabTest(ray.grid_origin, ray.grid_dir, T(vol.n));
  const T delta = Min(vol.size.x, Min(vol.size.y, vol.size.z)) / T(vol.n);
  March<T> m{s.t_min, s.t_max, delta, 0, s.hit};
  if (s.hit) m.count = static_cast<int>(Ceil((s.t_max - s.t_min) / delta));
  return m;
}

template <class T>
PERF_HD_INLINE MarchStep<T> StepAt(const March<T>& m, int k, const Jitter& jit) {
  const T start = m.t_min + T(k) * m.delta;
  const T len = Max(T(0), Min(m.delta, m.t_max - start));
  const T u = jit.enabled ? Uniform01<T>(jit.seed, jit.ray, static_cast<uint32_t>(k)) : T(0.5);
  return {start + u * len, len};
}

// Whether the trilinear support of grid point g (the cells TrilinearWeights reads) reaches a
// stored cell of a brick-sparse grid: the at most 2 x 2 x 2 bricks of its corner cells.
template <class T>
PERF_HD_INLINE bool ReachesStoredCell(const VolumeView<T>& vol, Vec3<T> g) {
  const int nb = vol.n / kBrickSide;
  int b0[3], b1[3];
  for (int a = 0; a < 3; ++a) {
    int lo, hi;
    T f;
    LinearCoord(g[a], vol.n, &lo, &hi, &f);
    b0[a] = lo / kBrickSide;
    b1[a] = hi / kBrickSide;
  }
  for (int c = 0; c < 8; ++c) {
    const int bi = c & 1 ? b1[0] : b0[0], bj = c & 2 ? b1[1] : b0[1], bk = c & 4 ? b1[2] : b0[2];
    if (vol.brick_slot[BrickOf(nb, bi, bj, bk)] >= 0) return true;
  }
  return false;
}

// The march index of the first sample at or after k (dir +1), or at or before k (dir -1), that a
// brick-sparse grid cannot skip, with its step in *st; march.count (or -1) when none is left. A
// sample whose trilinear support has no stored cell reads only zeros: it adds exact zeros to every
// sum of Forward and Backward, so skipping it changes nothing. By the empty-space table
// (ray_types.h SkipBlockOf): a sample in a stored brick is taken; one in a block that may read a
// stored cell is asked (ReachesStoredCell); from one in a block at distance d the march jumps to
// the sample whose segment holds the point where the ray leaves (enters) the cube of 2 d - 1
// blocks around it. The samples that are taken keep their index, hence their jitter: the sparse
// march equals the dense one wherever the skipped space is empty. Dense grids: k.
template <class T>
PERF_HD_INLINE int TakeSample(const VolumeView<T>& vol, const BoxRay<T>& ray, const March<T>& m, int k, int dir,
                              const Jitter& jit, MarchStep<T>* st) {
  while (k >= 0 && k < m.count) {
    *st = StepAt(m, k, jit);
    if (!vol.brick_slot) return k;
    const Vec3<T> g = ray.GridPoint(st->t);
    int cell[3];
    for (int a = 0; a < 3; ++a) cell[a] = static_cast<int>(Clamp(g[a], T(0), T(vol.n - 1)));  // >= 0: floor
    const int v = vol.skip_blocks[SkipBlockOf(vol.n, cell[0], cell[1], cell[2])];
    if (v == kStoredBlock) return k;
    if (v == kReadingBlock) {
      if (ReachesStoredCell(vol, g)) return k;
      k += dir;
      continue;
    }
    const int d = v - 1;
    T t_edge = dir > 0 ? T(3.0e38) : T(-3.0e38);
    for (int a = 0; a < 3; ++a) {
      const T dg = ray.grid_dir[a];
      if (dg == 0) continue;
      const int lo = (cell[a] / kSkipBlockSide - (d - 1)) * kSkipBlockSide;
      const int side = (2 * d - 1) * kSkipBlockSide;
      const T face = T(lo + ((dg > 0) == (dir > 0) ? side : 0));
      const T t = (face - ray.grid_origin[a]) / dg;
      t_edge = dir > 0 ? Min(t_edge, t) : Max(t_edge, t);
    }
    const T seg = (t_edge - m.t_min) / m.delta;
    if (dir > 0) {
      k = seg >= T(m.count) ? m.count : Max(k + 1, static_cast<int>(Floor(Max(seg, T(0)))));
    } else {
      k = seg < T(0) ? -1 : Min(k - 1, static_cast<int>(Floor(seg)));
    }
  }
  return k;
}

}  // namespace perf::recon
