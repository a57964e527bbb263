// Trilinear sampling of the voxel grid (DESIGN.md "Representation"): N^3 cells, each holding
// (r, g, b, sigma) at its centre (i + 0.5, j + 0.5, k + 0.5) in grid units, clamped at the
// border, stored densely or in bricks (ray_types.h). Returns the 8 cells and weights so
// derivatives can be scattered back; a cell of an inactive brick is -1 (it reads 0 and takes
// no derivative).
#pragma once

#include "recon_cuda/core/ray_types.h"

namespace perf::recon {

template <class T>
struct GridSample {
  int64_t cell[8];  // stored cell indices (-1: inactive), corner c = (c & 1, c >> 1 & 1, c >> 2) offsets from lo
  T w[8];           // weights, sum to 1
  int lo[3];        // the lower cell index per axis
  bool distinct;    // no axis is clamped to a single cell (only then are the 8 cells distinct)
};

// g: position in grid units, the box being [0, n]^3. brick_slot: the brick table of a sparse
// grid (ray_types.h), nullptr for a dense one.
template <class T>
PERF_HD_INLINE GridSample<T> TrilinearWeights(int n, const int32_t* brick_slot, Vec3<T> g) {
  int lo[3], hi[3];
  T f[3];
  for (int a = 0; a < 3; ++a) LinearCoord(g[a], n, &lo[a], &hi[a], &f[a]);
  GridSample<T> s;
  const T wx[2] = {1 - f[0], f[0]}, wy[2] = {1 - f[1], f[1]}, wz[2] = {1 - f[2], f[2]};
  if (brick_slot) {
    const int nb = n / kBrickSide;
    for (int c = 0; c < 8; ++c) {
      const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
      s.cell[c] = SparseCell(brick_slot, nb, dx ? hi[0] : lo[0], dy ? hi[1] : lo[1], dz ? hi[2] : lo[2]);
      s.w[c] = wx[dx] * wy[dy] * wz[dz];
    }
  } else {
    const int64_t base = GridCell(n, lo[0], lo[1], lo[2]);
    const int64_t ox = hi[0] - lo[0], oy = static_cast<int64_t>(hi[1] - lo[1]) * n,
                  oz = static_cast<int64_t>(hi[2] - lo[2]) * n * n;
    for (int c = 0; c < 8; ++c) {
      const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
      s.cell[c] = base + (dx ? ox : 0) + (dy ? oy : 0) + (dz ? oz : 0);
      s.w[c] = wx[dx] * wy[dy] * wz[dz];
    }
  }
  for (int a = 0; a < 3; ++a) s.lo[a] = lo[a];
  s.distinct = hi[0] != lo[0] && hi[1] != lo[1] && hi[2] != lo[2];
  return s;
}

// params: the grid part of x; out: (r, g, b, sigma).
template <class T>
PERF_HD_INLINE void GatherGrid(const T* params, const GridSample<T>& s, T out[4]) {
  for (int ch = 0; ch < 4; ++ch) out[ch] = 0;
  for (int c = 0; c < 8; ++c) {
    if (s.cell[c] < 0) continue;
    const T* p = params + GridParam(s.cell[c], 0);
    for (int ch = 0; ch < 4; ++ch) out[ch] += s.w[c] * p[ch];
  }
}

}  // namespace perf::recon
