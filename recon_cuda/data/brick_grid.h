// The layout of a brick-sparse grid on the host (ray_types.h "Brick-sparse grids"): which 8^3
// bricks of an N^3 grid hold parameters, the table the ray math reads, and the moves between the
// dense and the sparse storage of the grid's values.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "recon_cuda/core/ray_types.h"

namespace perf::recon {

struct BrickGrid {
  int n = 0;                    // cells per axis, a multiple of kBrickSide
  std::vector<int32_t> slot;    // [(n/8)^3], x fastest: the brick's slot, or kInactiveBrick
  std::vector<int64_t> bricks;  // the active bricks (BrickOf index) in slot order
  std::vector<uint8_t> skip_blocks;  // [(n/2)^3], x fastest: the march's empty-space table (SkipBlockOf)

  int nb() const { return n / kBrickSide; }
  int64_t ActiveBricks() const { return static_cast<int64_t>(bricks.size()); }
  int64_t GridParams() const { return SparseGridParams(ActiveBricks()); }
  bool operator==(const BrickGrid&) const = default;

  // Calls f(i, j, k, stored cell) for every cell of the active bricks, in storage order.
  template <class F>
  void ForEachCell(F&& f) const {
    const int b = nb();
    int64_t cell = 0;
    for (int64_t brick : bricks) {
      const int bi = static_cast<int>(brick % b) * kBrickSide, bj = static_cast<int>(brick / b % b) * kBrickSide,
                bk = static_cast<int>(brick / (int64_t{b} * b)) * kBrickSide;
      for (int z = 0; z < kBrickSide; ++z)
        for (int y = 0; y < kBrickSide; ++y)
          for (int x = 0; x < kBrickSide; ++x) f(bi + x, bj + y, bk + z, cell++);
    }
  }
};

// active: [(n/8)^3] flags, x fastest. Slots follow the brick order; the empty-space table is
// built from the same flags (ray_types.h). Throws InputError when n is not a positive multiple of
// 8 or `active` has the wrong size.
BrickGrid MakeBrickGrid(int n, const std::vector<uint8_t>& active);

// The grid part of x between the layouts: dense [n^3, 4] to sparse [active cells, 4] (the values
// of inactive bricks are dropped), and back (inactive cells 0).
template <class T>
std::vector<T> PackGrid(const BrickGrid& b, std::span<const T> dense) {
  std::vector<T> out(static_cast<size_t>(b.GridParams()));
  b.ForEachCell([&](int i, int j, int k, int64_t cell) {
    for (int ch = 0; ch < 4; ++ch) out[GridParam(cell, ch)] = dense[GridParam(GridCell(b.n, i, j, k), ch)];
  });
  return out;
}

template <class T>
std::vector<T> UnpackGrid(const BrickGrid& b, std::span<const T> sparse) {
  std::vector<T> out(static_cast<size_t>(GridParamCount(b.n)), T(0));
  b.ForEachCell([&](int i, int j, int k, int64_t cell) {
    for (int ch = 0; ch < 4; ++ch) out[GridParam(GridCell(b.n, i, j, k), ch)] = sparse[GridParam(cell, ch)];
  });
  return out;
}

}  // namespace perf::recon
