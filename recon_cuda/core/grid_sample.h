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
  for (int c = 0; c < 8; ++c) s.w[c] = wx[c & 1] * wy[(c >> 1) & 1] * wz[(c >> 2) & 1];
  for (int a = 0; a < 3; ++a) s.lo[a] = lo[a];
  s.distinct = hi[0] != lo[0] && hi[1] != lo[1] && hi[2] != lo[2];
  // Corner c's stored index is base + (dx ? ox : 0) + (dy ? oy : 0) + (dz ? oz : 0) in the dense
  // layout, and in a sparse grid's brick when all 8 corners lie in it (about 2/3 of the samples:
  // hi is lo or lo + 1, in lo's brick when they agree above the brick's 3 bits).
  int64_t base, ox = hi[0] - lo[0], oy = hi[1] - lo[1], oz = hi[2] - lo[2];
  if (!brick_slot) {
    base = GridCell(n, lo[0], lo[1], lo[2]);
    oy *= n;
    oz *= static_cast<int64_t>(n) * n;
  } else if ((lo[0] ^ hi[0]) < kBrickSide && (lo[1] ^ hi[1]) < kBrickSide && (lo[2] ^ hi[2]) < kBrickSide) {
    const int32_t slot = brick_slot[BrickOf(n / kBrickSide, lo[0] >> 3, lo[1] >> 3, lo[2] >> 3)];
    if (slot < 0) {  // one inactive brick
      for (int c = 0; c < 8; ++c) s.cell[c] = -1;
      return s;
    }
    base = static_cast<int64_t>(slot) * kBrickCells +
           (((lo[2] & 7) * kBrickSide + (lo[1] & 7)) * kBrickSide + (lo[0] & 7));
    oy *= kBrickSide;
    oz *= kBrickSide * kBrickSide;
  } else {  // the corners span two or more bricks: each looks its own up
    const int nb = n / kBrickSide;
    for (int c = 0; c < 8; ++c)
      s.cell[c] = SparseCell(brick_slot, nb, c & 1 ? hi[0] : lo[0], c & 2 ? hi[1] : lo[1], c & 4 ? hi[2] : lo[2]);
    return s;
  }
  for (int c = 0; c < 8; ++c) s.cell[c] = base + (c & 1 ? ox : 0) + (c & 2 ? oy : 0) + (c & 4 ? oz : 0);
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
