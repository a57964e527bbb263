#include "recon_cuda/data/brick_grid.h"

#include "common/errors.h"

namespace perf::recon {

BrickGrid MakeBrickGrid(int n, const std::vector<uint8_t>& active) {
  if (n <= 0 || n % kBrickSide != 0) {
    throw InputError("brick grid", "n", StrCat(n), StrCat("a sparse grid needs a positive multiple of ", kBrickSide,
                                                          " cells per axis"));
  }
  BrickGrid b;
  b.n = n;
  const int nb = b.nb();
  const int64_t count = BrickCount(n);
  if (static_cast<int64_t>(active.size()) != count) {
    throw InputError("brick grid", "active", StrCat(active.size(), " flags"), StrCat("expected ", count));
  }
  b.slot.assign(static_cast<size_t>(count), kSkipBrick);
  for (int64_t i = 0; i < count; ++i) {
    if (!active[i]) continue;
    b.slot[i] = static_cast<int32_t>(b.bricks.size());
    b.bricks.push_back(i);
  }
  // An inactive brick's octant o (per axis 0 or 1) reaches cells 4 o - 1 .. 4 o + 4 of it, so the
  // bricks o - 1 and o along each axis: its mask bit is set when one of those 2 x 2 x 2 is active.
  const auto active_at = [&](int i, int j, int k) {
    return i >= 0 && j >= 0 && k >= 0 && i < nb && j < nb && k < nb && active[BrickOf(nb, i, j, k)];
  };
  for (int bk = 0; bk < nb; ++bk) {
    for (int bj = 0; bj < nb; ++bj) {
      for (int bi = 0; bi < nb; ++bi) {
        int32_t& s = b.slot[BrickOf(nb, bi, bj, bk)];
        if (s >= 0) continue;
        int mask = 0;
        for (int o = 0; o < 8; ++o) {
          const int ox = o & 1, oy = (o >> 1) & 1, oz = o >> 2;
          bool reach = false;
          for (int c = 0; c < 8 && !reach; ++c) {
            reach = active_at(bi + ox - 1 + (c & 1), bj + oy - 1 + ((c >> 1) & 1), bk + oz - 1 + (c >> 2));
          }
          if (reach) mask |= 1 << o;
        }
        s = InactiveBrick(mask);
      }
    }
  }
  return b;
}

}  // namespace perf::recon
