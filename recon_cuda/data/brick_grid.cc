#include "recon_cuda/data/brick_grid.h"

#include <algorithm>

#include "common/errors.h"

namespace perf::recon {

namespace {

// Each skip brick's radius: its chessboard distance (in bricks) to the nearest brick that is not
// one, by a forward and a backward sweep over the 13 neighbours before (after) it, which is exact
// for that distance. Bricks outside the grid count as skip bricks (the march ends at the box).
void SetSkipRadii(BrickGrid* b) {
  const int nb = b->nb();
  std::vector<int> dist(b->slot.size());
  for (size_t i = 0; i < dist.size(); ++i) dist[i] = b->slot[i] == kSkipBrick ? kMaxSkipRadius : 0;  // the cap
  const auto sweep = [&](int sign) {
    for (int t = 0; t < nb * nb * nb; ++t) {
      const int idx = sign > 0 ? t : nb * nb * nb - 1 - t;
      const int i = idx % nb, j = idx / nb % nb, k = idx / (nb * nb);
      int& d = dist[idx];
      if (d == 0) continue;
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int before = (dz * nb + dy) * nb + dx;  // neighbours already swept: index offset < 0 (> 0)
            if (before * sign >= 0) continue;
            const int x = i + dx, y = j + dy, z = k + dz;
            if (x < 0 || y < 0 || z < 0 || x >= nb || y >= nb || z >= nb) continue;
            d = std::min(d, dist[BrickOf(nb, x, y, z)] + 1);
          }
    }
  };
  sweep(1);
  sweep(-1);
  for (size_t i = 0; i < dist.size(); ++i) {
    if (dist[i] > 0) b->slot[i] = SkipBrick(dist[i]);
  }
}

}  // namespace

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
  SetSkipRadii(&b);
  return b;
}

}  // namespace perf::recon
