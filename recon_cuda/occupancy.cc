#include "recon_cuda/occupancy.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "common/errors.h"

namespace perf::recon {

std::shared_ptr<const BrickGrid> OccupiedBricks(const VolumeShape& shape, const VolumeGeometry& geometry,
                                                std::span<const float> x, int n_next, const OccupancyOptions& o) {
  PERF_CHECK(static_cast<int64_t>(x.size()) == shape.ParamCount());
  PERF_CHECK(n_next > 0 && n_next % kBrickSide == 0);
  const int n = shape.n;
  const float side = std::min({geometry.box.size.x, geometry.box.size.y, geometry.box.size.z}) / static_cast<float>(n);
  // sigma * side >= -log(1 - min_opacity)
  const float min_sigma = -std::log1p(-std::clamp(o.min_opacity, 0.f, 0.999999f)) / side;

  // The occupied cells of the fitted level and their 3-D prefix sum, so that each brick asks "any
  // occupied cell in this box?" in O(1).
  const int64_t n1 = n + 1;
  std::vector<int32_t> sum(static_cast<size_t>(n1 * n1 * n1), 0);
  const auto at = [&](int i, int j, int k) -> int32_t& { return sum[(static_cast<int64_t>(k) * n1 + j) * n1 + i]; };
  std::vector<uint8_t> occupied(static_cast<size_t>(n) * n * n, 0);
  ForEachStoredCell(shape, [&](int i, int j, int k, int64_t cell) {
    occupied[GridCell(n, i, j, k)] = x[GridParam(cell, 3)] >= min_sigma;
  });
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        at(i + 1, j + 1, k + 1) = occupied[GridCell(n, i, j, k)] + at(i, j + 1, k + 1) + at(i + 1, j, k + 1) +
                                  at(i + 1, j + 1, k) - at(i, j, k + 1) - at(i, j + 1, k) - at(i + 1, j, k) +
                                  at(i, j, k);
  const auto count = [&](int i0, int j0, int k0, int i1, int j1, int k1) {  // cells [i0, i1) x ...
    return at(i1, j1, k1) - at(i0, j1, k1) - at(i1, j0, k1) - at(i1, j1, k0) + at(i0, j0, k1) + at(i0, j1, k0) +
           at(i1, j0, k0) - at(i0, j0, k0);
  };

  // Brick b of the next level spans next cells [8 b, 8 b + 8), fitted cells [8 b n / n_next,
  // (8 b + 8) n / n_next) (rounded outwards), grown by the dilation.
  const int nb = n_next / kBrickSide;
  const auto range = [&](int b, int* lo, int* hi) {
    *lo = std::clamp(static_cast<int>(std::floor(double(b) * kBrickSide * n / n_next)) - o.dilation, 0, n);
    *hi = std::clamp(static_cast<int>(std::ceil(double(b + 1) * kBrickSide * n / n_next)) + o.dilation, 0, n);
  };
  std::vector<uint8_t> active(static_cast<size_t>(nb) * nb * nb, 0);
  for (int bk = 0; bk < nb; ++bk) {
    for (int bj = 0; bj < nb; ++bj) {
      for (int bi = 0; bi < nb; ++bi) {
        int i0, i1, j0, j1, k0, k1;
        range(bi, &i0, &i1);
        range(bj, &j0, &j1);
        range(bk, &k0, &k1);
        active[BrickOf(nb, bi, bj, bk)] = count(i0, j0, k0, i1, j1, k1) > 0;
      }
    }
  }
  return std::make_shared<const BrickGrid>(MakeBrickGrid(n_next, active));
}

}  // namespace perf::recon
