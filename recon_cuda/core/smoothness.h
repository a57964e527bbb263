// Smoothness as least-squares residuals, so that the background and grid generalise: for
// every pair (a, b) of neighbouring parameters of one kind and channel, the residual
// sqrt(w_kind) (x_a - x_b). Neighbours are the 6 face-adjacent stored cells of the grid and the 4
// edge-adjacent texels of a shell's cube map, across the seams between faces too (every texel
// has exactly 4). The term is quadratic, so it enters Gauss-Newton exactly: its J^T J is the
// weighted graph Laplacian L (a stencil, never formed), its J^T r is L x, its diagonal is w times
// the number of neighbours and its cost is x^T L x / 2. Host and device share these functions
// (STYLE.md "Host and device"), one parameter per call, so nothing is written twice.
#pragma once

#include <stdint.h>

#include "recon_cuda/core/param_ops.h"
#include "recon_cuda/core/ray_types.h"
#include "recon_cuda/core/shells.h"

namespace perf::recon {

// The weight w of each kind's pairs (0: no smoothness for that kind). The photos' exposures have
// no neighbours: their weight is a prior's, the residual sqrt(w) x_i (gain 1, offset 0), which
// fixes the gauge (all gains against all colours) and keeps the transforms near the identity.
// The photos' pose corrections have a prior of the same form toward the imported pose, one
// weight for the rotations, one for the centres and one for the focal lengths: it holds the set
// of cameras where the photos do not say otherwise, and fixes the gauge (all cameras moving
// together against the volume).
struct SmoothnessWeights {
  float grid_colour = 0, grid_density = 0, shell_colour = 0, shell_opacity = 0, exposure = 0;
  float pose_rotation = 0, pose_centre = 0, pose_focal = 0;

  PERF_HD_INLINE bool Any() const {
    return grid_colour > 0 || grid_density > 0 || shell_colour > 0 || shell_opacity > 0 || exposure > 0 ||
           pose_rotation > 0 || pose_centre > 0 || pose_focal > 0;
  }
  PERF_HD_INLINE float Of(ParamKind k) const {
    switch (k) {
      case ParamKind::kGridColour:
      case ParamKind::kGridSh: return grid_colour;  // a view-dependent colour is smoothed as the colour
      case ParamKind::kGridDensity: return grid_density;
      case ParamKind::kShellColour: return shell_colour;
      case ParamKind::kShellOpacity: return shell_opacity;
      case ParamKind::kPoseRotation: return pose_rotation;
      case ParamKind::kPoseCentre: return pose_centre;
      case ParamKind::kPoseFocal: return pose_focal;
      default: return exposure;
    }
  }
};

// What the stencil reads of the level's layout (ray_types.h): a dense grid (slot == nullptr) or a
// brick-sparse one (its brick table and, slot by slot, the brick each slot holds).
struct SmoothnessLayout {
  int n = 0, m = 0, num_shells = 0;
  ParamLayout params;               // where the shells, spherical harmonics and exposures start
  int sh_degree = 0;                // the spherical harmonics' degree (0: none)
  const int32_t* slot = nullptr;    // [(n/8)^3] brick table (BrickGrid::slot)
  const int64_t* bricks = nullptr;  // [active bricks] brick index of each slot (BrickGrid::bricks)
};

// The stored cells next to stored cell `cell` (up to 6) into out; returns how many.
PERF_HD_INLINE int GridNeighbours(const SmoothnessLayout& l, int64_t cell, int64_t out[6]) {
  int i, j, k;
  if (l.slot == nullptr) {
    i = static_cast<int>(cell % l.n);
    j = static_cast<int>(cell / l.n % l.n);
    k = static_cast<int>(cell / (static_cast<int64_t>(l.n) * l.n));
  } else {
    const int nb = l.n / kBrickSide;
    const int64_t brick = l.bricks[cell / kBrickCells];
    const int local = static_cast<int>(cell % kBrickCells);
    i = static_cast<int>(brick % nb) * kBrickSide + (local & 7);
    j = static_cast<int>(brick / nb % nb) * kBrickSide + ((local >> 3) & 7);
    k = static_cast<int>(brick / (static_cast<int64_t>(nb) * nb)) * kBrickSide + (local >> 6);
  }
  int count = 0;
  for (int d = 0; d < 6; ++d) {
    const int s = (d & 1) ? 1 : -1, axis = d >> 1;
    const int a = i + (axis == 0 ? s : 0), b = j + (axis == 1 ? s : 0), c = k + (axis == 2 ? s : 0);
    if (a < 0 || b < 0 || c < 0 || a >= l.n || b >= l.n || c >= l.n) continue;
    const int64_t q = l.slot == nullptr ? GridCell(l.n, a, b, c) : SparseCell(l.slot, l.n / kBrickSide, a, b, c);
    if (q >= 0) out[count++] = q;
  }
  return count;
}

// The texel across the edge of face `face` that texel (iu, iv) steps over by (du, dv) (one of
// them +-1): the point on the shared edge at the texel's centre along it, pushed a hair into the
// next face, is looked up there. Both faces split the edge into the same m segments, so the
// pairing is symmetric.
PERF_HD_INLINE void SeamNeighbour(int m, int face, int iu, int iv, int du, int dv, int* nface, int* nu, int* nv) {
  const double push = 1e-3 / m;
  double u = (iu + 0.5) / m, v = (iv + 0.5) / m;
  if (du != 0) u = du > 0 ? 1 + push : -push;
  if (dv != 0) v = dv > 0 ? 1 + push : -push;
  const CubeCoord<double> c = DirectionToCube(CubeToDirection(CubeCoord<double>{face, u, v}));
  *nface = c.face;
  *nu = Clamp(static_cast<int>(Floor(c.u * m)), 0, m - 1);
  *nv = Clamp(static_cast<int>(Floor(c.v * m)), 0, m - 1);
}

// The 4 texels of the same shell next to texel `texel` (index ((s 6 + f) m + v) m + u), as
// texel indices.
PERF_HD_INLINE void ShellNeighbours(const SmoothnessLayout& l, int64_t texel, int64_t out[4]) {
  const int64_t mm = static_cast<int64_t>(l.m) * l.m;
  const int u = static_cast<int>(texel % l.m), v = static_cast<int>(texel / l.m % l.m);
  const int64_t face_index = texel / mm;  // s 6 + f
  const int face = static_cast<int>(face_index % 6);
  const int64_t shell_base = (face_index - face) * mm;
  for (int d = 0; d < 4; ++d) {
    const int du = d == 0 ? -1 : d == 1 ? 1 : 0, dv = d == 2 ? -1 : d == 3 ? 1 : 0;
    int f = face, a = u + du, b = v + dv;
    if (a < 0 || b < 0 || a >= l.m || b >= l.m) SeamNeighbour(l.m, face, u, v, du, dv, &f, &a, &b);
    out[d] = shell_base + (static_cast<int64_t>(f) * l.m + b) * l.m + a;
  }
}

// The parameters next to parameter i (same kind and channel) into out; returns how many. A
// spherical-harmonic coefficient's are the same band and channel of the neighbouring cells (a
// padding zero has none).
PERF_HD_INLINE int ParamNeighbours(const SmoothnessLayout& l, int64_t i, int64_t out[6]) {
  if (i >= l.params.sh_start && i < l.params.exposure_start) {
    const int stride = ShStride(l.sh_degree);
    const int64_t cell = (i - l.params.sh_start) / stride;
    const int j = static_cast<int>((i - l.params.sh_start) % stride);
    if (j >= 3 * ShBands(l.sh_degree)) return 0;
    const int count = GridNeighbours(l, cell, out);
    for (int k = 0; k < count; ++k) out[k] = l.params.sh_start + stride * out[k] + j;
    return count;
  }
  const int ch = static_cast<int>(i % 4);
  if (i < l.params.grid_params) {
    const int count = GridNeighbours(l, i / 4, out);
    for (int k = 0; k < count; ++k) out[k] = GridParam(out[k], ch);
    return count;
  }
  ShellNeighbours(l, (i - l.params.grid_params) / 4, out);
  for (int k = 0; k < 4; ++k) out[k] = l.params.grid_params + 4 * out[k] + ch;
  return 4;
}

// Parameter i's row of the term at v: *lap = w sum_j (v_i - v_j) (row i of L v), *degree = w
// times the number of neighbours (L's diagonal), and the return value is i's share of
// v^T L v / 2 (each pair's w (v_a - v_b)^2 / 2 split between its two ends). An exposure's or a
// pose's row is its prior's: w v_i, w and w v_i^2 / 2.
PERF_HD_INLINE double SmoothnessRow(const SmoothnessLayout& l, const SmoothnessWeights& weights, const float* v,
                                    int64_t i, float* lap, float* degree) {
  *lap = 0;
  *degree = 0;
  const float w = weights.Of(KindOfParam(l.params, i));
  if (!(w > 0)) return 0;
  if (i >= l.params.exposure_start) {  // the prior: L = w I
    *lap = w * v[i];
    *degree = w;
    return 0.5 * w * static_cast<double>(v[i]) * v[i];
  }
  int64_t nbr[6];
  const int count = ParamNeighbours(l, i, nbr);
  float sum = 0;
  double energy = 0;
  for (int k = 0; k < count; ++k) {
    const float d = v[i] - v[nbr[k]];
    sum += d;
    energy += static_cast<double>(d) * d;
  }
  *lap = w * sum;
  *degree = w * static_cast<float>(count);
  return 0.25 * w * energy;
}

}  // namespace perf::recon
