#include "recon_cuda/brick_grid.h"

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
  const int64_t count = static_cast<int64_t>(nb) * nb * nb;
  if (static_cast<int64_t>(active.size()) != count) {
    throw InputError("brick grid", "active", StrCat(active.size(), " flags"), StrCat("expected ", count));
  }
  b.slot.assign(static_cast<size_t>(count), kSkipBrick);
  for (int64_t i = 0; i < count; ++i) {
    if (!active[i]) continue;
    b.slot[i] = static_cast<int32_t>(b.bricks.size());
    b.bricks.push_back(i);
  }
  for (int64_t brick : b.bricks) {
    const int bi = static_cast<int>(brick % nb), bj = static_cast<int>(brick / nb % nb),
              bk = static_cast<int>(brick / (int64_t{nb} * nb));
    for (int dk = -1; dk <= 1; ++dk) {
      for (int dj = -1; dj <= 1; ++dj) {
        for (int di = -1; di <= 1; ++di) {
          const int i = bi + di, j = bj + dj, k = bk + dk;
          if (i < 0 || j < 0 || k < 0 || i >= nb || j >= nb || k >= nb) continue;
          int32_t& s = b.slot[BrickOf(nb, i, j, k)];
          if (s == kSkipBrick) s = kEmptyBrick;
        }
      }
    }
  }
  return b;
}

BrickGrid FullBrickGrid(int n) {
  const int nb = n / kBrickSide;
  return MakeBrickGrid(n, std::vector<uint8_t>(static_cast<size_t>(nb) * nb * nb, 1));
}

}  // namespace perf::recon
