#include "recon_cuda/data/brick_grid.h"

#include <algorithm>

#include "common/errors.h"

namespace perf::recon {

namespace {

// The march's empty-space table (ray_types.h SkipBlockOf). Block B's samples read cells 2 B - 1 ..
// 2 B + 2 per axis (a sample reads cells within half a cell of it), so a block outside the active
// bricks may read one when a brick over that range is active. The distances: two sweeps over the 13
// neighbours before (after) a block, which is exact for the chessboard distance.
std::vector<uint8_t> SkipBlocks(int n, const std::vector<uint8_t>& active) {
  const int nb = n / kBrickSide, nk = n / kSkipBlockSide;
  const int64_t blocks = int64_t{nk} * nk * nk;
  const auto bricks_read = [&](int blk, int* lo, int* hi) {
    *lo = std::max(0, (kSkipBlockSide * blk - 1) / kBrickSide);
    *hi = std::min(nb - 1, (kSkipBlockSide * blk + kSkipBlockSide) / kBrickSide);
  };
  constexpr uint8_t kFar = 255;  // the distance, capped (the table caps it lower)
  std::vector<uint8_t> dist(static_cast<size_t>(blocks));  // 0: stored or reading
  std::vector<uint8_t> out(static_cast<size_t>(blocks));
  for (int64_t idx = 0; idx < blocks; ++idx) {
    const int i = static_cast<int>(idx % nk), j = static_cast<int>(idx / nk % nk),
              k = static_cast<int>(idx / (int64_t{nk} * nk));
    const int per_brick = kBrickSide / kSkipBlockSide;
    if (active[BrickOf(nb, i / per_brick, j / per_brick, k / per_brick)]) {
      out[idx] = kStoredBlock;
      continue;
    }
    int lo[3], hi[3];
    bricks_read(i, &lo[0], &hi[0]);
    bricks_read(j, &lo[1], &hi[1]);
    bricks_read(k, &lo[2], &hi[2]);
    bool reads = false;
    for (int z = lo[2]; z <= hi[2] && !reads; ++z)
      for (int y = lo[1]; y <= hi[1] && !reads; ++y)
        for (int x = lo[0]; x <= hi[0] && !reads; ++x) reads = active[BrickOf(nb, x, y, z)];
    out[idx] = kReadingBlock;
    dist[idx] = reads ? 0 : kFar;
  }
  const auto sweep = [&](int sign) {
    for (int64_t t = 0; t < blocks; ++t) {
      const int64_t idx = sign > 0 ? t : blocks - 1 - t;
      const int i = static_cast<int>(idx % nk), j = static_cast<int>(idx / nk % nk),
                k = static_cast<int>(idx / (int64_t{nk} * nk));
      uint8_t& d = dist[idx];
      if (d == 0) continue;
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int before = (dz * nk + dy) * nk + dx;  // neighbours already swept: index offset < 0 (> 0)
            if (before * sign >= 0) continue;
            const int x = i + dx, y = j + dy, z = k + dz;
            if (x < 0 || y < 0 || z < 0 || x >= nk || y >= nk || z >= nk) continue;
            d = static_cast<uint8_t>(std::min<int>(d, dist[(int64_t{z} * nk + y) * nk + x] + 1));
          }
    }
  };
  sweep(1);
  sweep(-1);
  for (int64_t idx = 0; idx < blocks; ++idx) {
    if (dist[idx] > 0) out[idx] = static_cast<uint8_t>(std::min(1 + dist[idx], int{kMaxBlockValue}));
  }
  return out;
}

}  // namespace

BrickGrid MakeBrickGrid(int n, const std::vector<uint8_t>& active) {
  if (n <= 0 || n % kBrickSide != 0) {
    throw InputError("brick grid", "n", StrCat(n), StrCat("a sparse grid needs a positive multiple of ", kBrickSide,
                                                          " cells per axis"));
  }
  BrickGrid b;
  b.n = n;
  const int64_t count = BrickCount(n);
  if (static_cast<int64_t>(active.size()) != count) {
    throw InputError("brick grid", "active", StrCat(active.size(), " flags"), StrCat("expected ", count));
  }
  b.slot.assign(static_cast<size_t>(count), kInactiveBrick);
  for (int64_t i = 0; i < count; ++i) {
    if (!active[i]) continue;
    b.slot[i] = static_cast<int32_t>(b.bricks.size());
    b.bricks.push_back(i);
  }
  b.skip_blocks = SkipBlocks(n, active);
  return b;
}

}  // namespace perf::recon
