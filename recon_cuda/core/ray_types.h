// Small value types, scalar helpers, the jitter hash and the parameter layout shared by the
// per-ray math (ray_math.h, grid_sample.h, shells.h). Host and device; templated on the scalar
// (float on the GPU, double in the tests). No std containers, no exceptions, no Eigen.
#pragma once

#include <math.h>
#include <stdint.h>

#include "recon_cuda/core/hd.h"

namespace perf::recon {

// Plain C math overloads: callable from device code without relying on std:: in kernels.
PERF_HD_INLINE float Exp(float x) { return expf(x); }
PERF_HD_INLINE double Exp(double x) { return exp(x); }
PERF_HD_INLINE float Sqrt(float x) { return sqrtf(x); }
PERF_HD_INLINE double Sqrt(double x) { return sqrt(x); }
PERF_HD_INLINE float Floor(float x) { return floorf(x); }
PERF_HD_INLINE double Floor(double x) { return floor(x); }
PERF_HD_INLINE float Ceil(float x) { return ceilf(x); }
PERF_HD_INLINE double Ceil(double x) { return ceil(x); }
PERF_HD_INLINE float Abs(float x) { return fabsf(x); }
PERF_HD_INLINE float Sin(float x) { return sinf(x); }
PERF_HD_INLINE double Sin(double x) { return sin(x); }
PERF_HD_INLINE float Cos(float x) { return cosf(x); }
PERF_HD_INLINE double Cos(double x) { return cos(x); }
PERF_HD_INLINE double Abs(double x) { return fabs(x); }
template <class T>
PERF_HD_INLINE T Min(T a, T b) { return b < a ? b : a; }
template <class T>
PERF_HD_INLINE T Max(T a, T b) { return a < b ? b : a; }
template <class T>
PERF_HD_INLINE T Clamp(T x, T lo, T hi) { return Min(Max(x, lo), hi); }

template <class T>
struct Vec3 {
  T x, y, z;
  PERF_HD_INLINE T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  PERF_HD_INLINE T& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};
template <class T>
PERF_HD_INLINE Vec3<T> operator+(Vec3<T> a, Vec3<T> b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class T>
PERF_HD_INLINE Vec3<T> operator-(Vec3<T> a, Vec3<T> b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class T>
PERF_HD_INLINE Vec3<T> operator*(Vec3<T> a, T s) { return {a.x * s, a.y * s, a.z * s}; }
template <class T>
PERF_HD_INLINE Vec3<T> Mul(Vec3<T> a, Vec3<T> b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
template <class T>
PERF_HD_INLINE Vec3<T> Div(Vec3<T> a, Vec3<T> b) { return {a.x / b.x, a.y / b.y, a.z / b.z}; }
template <class T>
PERF_HD_INLINE T Dot(Vec3<T> a, Vec3<T> b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <class T>
PERF_HD_INLINE Vec3<T> Normalized(Vec3<T> a) { return a * (T(1) / Sqrt(Dot(a, a))); }

// Row-major 3x3.
template <class T>
struct Mat3 {
  T m[9];
};
template <class T>
PERF_HD_INLINE Vec3<T> MulMat(const Mat3<T>& r, Vec3<T> v) {
  return {r.m[0] * v.x + r.m[1] * v.y + r.m[2] * v.z, r.m[3] * v.x + r.m[4] * v.y + r.m[5] * v.z,
          r.m[6] * v.x + r.m[7] * v.y + r.m[8] * v.z};
}
template <class T>
PERF_HD_INLINE Vec3<T> MulMatTransposed(const Mat3<T>& r, Vec3<T> v) {
  return {r.m[0] * v.x + r.m[3] * v.y + r.m[6] * v.z, r.m[1] * v.x + r.m[4] * v.y + r.m[7] * v.z,
          r.m[2] * v.x + r.m[5] * v.y + r.m[8] * v.z};
}

// Clamped linear interpolation along one axis of n samples at positions i + 0.5 (cell or texel
// centres), s in sample units: values below the first centre or beyond the last take the border
// sample. lo == hi at the border (and when n == 1); f is the weight of hi.
template <class T>
PERF_HD_INLINE void LinearCoord(T s, int n, int* lo, int* hi, T* f) {
  const T c = Clamp(s - T(0.5), T(0), T(n - 1));
  // c >= 0, so truncation is floor (and needs no libm call where floorf has no instruction).
  // A NaN s gives c = NaN whose cast is unspecified: the index is clamped regardless.
  int i = static_cast<int>(c);
  i = i < 0 ? 0 : (i > n - 1 ? n - 1 : i);
  *lo = i;
  *hi = i + 1 < n ? i + 1 : n - 1;
  *f = c - T(i);
}

// Jitter: a stateless hash of (seed, ray, sample) so that every pass of one Gauss-Newton
// iteration sees the same random numbers (DESIGN.md "Gauss-Newton step"). murmur3's fmix32
// finaliser applied to a chained combination of the three words.
PERF_HD_INLINE uint32_t Fmix32(uint32_t h) {
  h ^= h >> 16;
  h *= 0x85ebca6bu;
  h ^= h >> 13;
  h *= 0xc2b2ae35u;
  h ^= h >> 16;
  return h;
}
PERF_HD_INLINE uint32_t Hash(uint32_t seed, uint32_t ray, uint32_t sample) {
  uint32_t h = Fmix32(seed * 0x9e3779b9u + 0x7f4a7c15u);
  h = Fmix32(h ^ (ray * 0xcc9e2d51u + 0x1b873593u));
  return Fmix32(h ^ (sample * 0x27d4eb2fu + 0x165667b1u));
}
// The top 24 bits as a float in [0, 1): exact in float, never rounds up to 1.
PERF_HD_INLINE float HashToUnit(uint32_t h) { return static_cast<float>(h >> 8) * (1.0f / 16777216.0f); }
template <class T>
PERF_HD_INLINE T Uniform01(uint32_t seed, uint32_t ray, uint32_t sample) {
  return static_cast<T>(HashToUnit(Hash(seed, ray, sample)));
}

// Parameter layout (one flat vector x per backend, DESIGN.md "Representation"):
//   grid cell (i, j, k), x fastest, cell = (k N + j) N + i, holds (r, g, b, sigma) at 4 cell + ch;
//   after the grid, shell s (0 innermost), face f (see shells.h), texel (u, v) holds (r, g, b, a)
//   at 4 N^3 + 4 ((s 6 + f) M^2 + v M + u) + ch;
//   after the shells, the grid's spherical harmonics beyond the constant when solved (ShParam),
//   then the photos' exposures when solved (ExposureParam), then their poses when refined
//   (PoseParam).
// 64-bit indices: 4 N^3 overflows 32 bits from N = 1024.
PERF_HD_INLINE int64_t GridCell(int n, int i, int j, int k) {
  return (static_cast<int64_t>(k) * n + j) * n + i;
}
PERF_HD_INLINE int64_t GridParam(int64_t cell, int ch) { return 4 * cell + ch; }
PERF_HD_INLINE int64_t GridParamCount(int n) { return 4 * static_cast<int64_t>(n) * n * n; }
// grid_params: where the shells start (GridParamCount(n) for a dense grid, SparseGridParams).
PERF_HD_INLINE int64_t ShellParamAt(int64_t grid_params, int m, int shell, int face, int u, int v, int ch) {
  return grid_params + 4 * ((static_cast<int64_t>(shell) * 6 + face) * m * m + static_cast<int64_t>(v) * m + u) + ch;
}
PERF_HD_INLINE int64_t ShellParam(int n, int m, int shell, int face, int u, int v, int ch) {
  return ShellParamAt(GridParamCount(n), m, shell, face, u, v, ch);
}
PERF_HD_INLINE int64_t ParamCount(int n, int m, int num_shells) {
  return GridParamCount(n) + 4 * static_cast<int64_t>(num_shells) * 6 * m * m;
}
// View-dependent colour (--sh-degree): real spherical harmonics of degree 1 or 2 beyond
// each stored cell's colour (its constant term), after the shells: stored cell c holds ShStride
// values at sh_start + ShStride c: band k (from 0, the first beyond the constant) channel ch at
// 3 k + ch, then zeros up to a multiple of 4 (float4 atomics; they never move). A sample's colour
// is the trilinear colour plus sum_k Y_k(d) times the trilinear band k, d the ray's direction in
// the box frame.
PERF_HD_INLINE int ShBands(int degree) { return (degree + 1) * (degree + 1) - 1; }
PERF_HD_INLINE int ShStride(int degree) { return (3 * ShBands(degree) + 3) / 4 * 4; }
inline constexpr int kMaxShBands = 8;    // degree 2
inline constexpr int kMaxShStride = 24;  // ShStride(2)
PERF_HD_INLINE int64_t ShParam(int64_t sh_start, int degree, int64_t cell, int band, int ch) {
  return sh_start + ShStride(degree) * cell + 3 * band + ch;
}
// Y_k(d) of the bands beyond the constant, d a unit vector (the real basis of graphics, e.g.
// Sloan's "Stupid spherical harmonics tricks", without the constant's 0.282, which the colour
// absorbs). Returns ShBands(degree).
template <class T>
PERF_HD_INLINE int ShBasis(int degree, Vec3<T> d, T* y) {
  if (degree < 1) return 0;
  const T c1 = T(0.4886025119029199);
  y[0] = -c1 * d.y;
  y[1] = c1 * d.z;
  y[2] = -c1 * d.x;
  if (degree < 2) return 3;
  y[3] = T(1.0925484305920792) * d.x * d.y;
  y[4] = T(-1.0925484305920792) * d.y * d.z;
  y[5] = T(0.31539156525252005) * (2 * d.z * d.z - d.x * d.x - d.y * d.y);
  y[6] = T(-1.0925484305920792) * d.x * d.z;
  y[7] = T(0.5462742152960396) * (d.x * d.x - d.y * d.y);
  return 8;
}

// Per-photo exposure, after the grid's spherical harmonics (or the shells): training photo
// `slot` (its index among the scene's training photos, scene.json order) holds kExposureValues
// values at exposure_start + 8 slot: the gain offsets gamma (r, g, b), 0, the colour offsets
// b (r, g, b), 0. Its pixels are modelled as (1 + gamma_c) H_c + b_c (ray_math.h
// ColourTransform). The two zeros keep each group of 4 aligned (float4 atomics); they stay 0 (no
// residual depends on them).
inline constexpr int kExposureValues = 8;
PERF_HD_INLINE int64_t ExposureParam(int64_t exposure_start, int slot) {
  return exposure_start + static_cast<int64_t>(kExposureValues) * slot;
}

// Per-photo pose correction (--refine-poses), after the exposures: training photo `slot` holds
// kPoseValues values at pose_start + 8 slot: a rotation vector omega (3), the log f of its focal
// length's scale (--refine-intrinsics focal; held at 0 otherwise), then the camera centre's
// offset c (3), 0, all in the box frame. The photo's rays leave from o + s c (s: the box's
// shortest side, VolumeView::PoseScale, so that c is in box units) in the direction
// exp([omega]x) d_f, d_f the imported camera's box-frame direction d with the focal length
// scaled by exp(f) (pose.h ApplyPose). The zero keeps each group of 4 aligned, as the exposures'
// do.
inline constexpr int kPoseValues = 8;
PERF_HD_INLINE int64_t PoseParam(int64_t pose_start, int slot) {
  return pose_start + static_cast<int64_t>(kPoseValues) * slot;
}

// Brick-sparse grids (DESIGN.md "Representation"): the N^3 cells are grouped in bricks
// of 8^3 (OpenVDB's leaf), N a multiple of 8. Only active bricks hold parameters: brick slot s
// holds its cells at s 512 + (z 8 + y) 8 + x (local coordinates), each cell 4 values as in the
// dense layout, and the shells follow the last slot. The brick table [(N/8)^3] gives each brick's
// slot (>= 0), or kInactiveBrick for a brick that reads as 0 in every channel.
inline constexpr int kBrickSide = 8;
inline constexpr int kBrickCells = kBrickSide * kBrickSide * kBrickSide;
inline constexpr int32_t kInactiveBrick = -1;

// The march's empty-space table (ray_march.h TakeSample), one byte per block of kSkipBlockSide^3
// cells [(N/2)^3], x fastest: kStoredBlock for a block of an active brick; kReadingBlock for one
// outside them a sample in which may read a stored cell (a sample reads cells within half a cell
// of it); else 1 + its chessboard distance d in blocks to the nearest block of either kind,
// capped at kMaxBlockValue: the cube of 2 d - 1 blocks around it holds no sample that reads a
// stored cell.
inline constexpr int kSkipBlockSide = 2;
inline constexpr uint8_t kStoredBlock = 0, kReadingBlock = 1, kMaxBlockValue = 255;
static_assert(kBrickSide % kSkipBlockSide == 0, "a block lies in one brick");
PERF_HD_INLINE int64_t SkipBlockOf(int n, int i, int j, int k) {
  const int64_t nk = n / kSkipBlockSide;
  return (k / kSkipBlockSide * nk + j / kSkipBlockSide) * nk + i / kSkipBlockSide;
}

PERF_HD_INLINE int64_t SparseGridParams(int64_t active_bricks) { return 4 * kBrickCells * active_bricks; }
// The bricks of an n^3 grid, (n / 8)^3.
PERF_HD_INLINE int64_t BrickCount(int n) {
  const int64_t nb = n / kBrickSide;
  return nb * nb * nb;
}
PERF_HD_INLINE int64_t BrickOf(int nb, int bi, int bj, int bk) { return (static_cast<int64_t>(bk) * nb + bj) * nb + bi; }
// The stored cell of grid cell (i, j, k) in a brick-sparse grid, or -1 when its brick is inactive.
PERF_HD_INLINE int64_t SparseCell(const int32_t* brick_slot, int nb, int i, int j, int k) {
  const int32_t slot = brick_slot[BrickOf(nb, i >> 3, j >> 3, k >> 3)];
  if (slot < 0) return -1;
  return static_cast<int64_t>(slot) * kBrickCells + (((k & 7) * kBrickSide + (j & 7)) * kBrickSide + (i & 7));
}

}  // namespace perf::recon
