// Brick-sparse grids (recon_cuda/data/brick_grid.h, ray_types.h): the table's marks, the moves between
// the dense and the sparse layout, and the per-ray math on the sparse layout in double: the
// march that skips empty bricks equals the dense march wherever the skipped space is empty (the
// same residuals and the same J^T r, bit for bit), and every partial matches central differences.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <span>
#include <vector>

#include "common/errors.h"
#include "recon_cuda/core/ray_math.h"
#include "recon_cuda/data/brick_grid.h"
#include "tests/recon/per_param_visitor.h"
#include "tests/recon/random_rays.h"

namespace perf::recon {
namespace {

using V3 = Vec3<double>;

// A tilted, non-cubic box whose grid holds random values in the active bricks and zeros (every
// channel) elsewhere, stored both ways, and two shells.
struct SparseScene {
  BoxFrame<double> box;
  BrickGrid bricks;
  std::vector<double> dense, sparse;
  VolumeView<double> dense_view{}, sparse_view{};

  SparseScene(std::mt19937& rng, int n, const std::vector<uint8_t>& active, double max_sigma, int m = 4) {
    box.center = {0.3, -0.2, 0.1};
    const double c = std::cos(0.5), s = std::sin(0.5);
    box.world_from_box = {{c, -s, 0, s * 0.8, c * 0.8, -0.6, s * 0.6, c * 0.6, 0.8}};  // two rotations
    box.size = {2.0, 1.6, 1.4};
    bricks = MakeBrickGrid(n, active);
    const int64_t shells = 4 * 2 * 6 * int64_t{m} * m;
    dense.assign(static_cast<size_t>(GridParamCount(n) + shells), 0.0);
    std::uniform_real_distribution<double> colour(0.1, 0.9), sigma(0.0, max_sigma), opacity(0.2, 0.8);
    for (int k = 0; k < n; ++k) {
      for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
          if (SparseCell(bricks.slot.data(), bricks.nb(), i, j, k) < 0) continue;
          const int64_t cell = GridCell(n, i, j, k);
          for (int ch = 0; ch < 3; ++ch) dense[GridParam(cell, ch)] = colour(rng);
          dense[GridParam(cell, 3)] = sigma(rng);
        }
      }
    }
    for (int64_t i = GridParamCount(n); i < static_cast<int64_t>(dense.size()); i += 4) {
      for (int ch = 0; ch < 3; ++ch) dense[i + ch] = colour(rng);
      dense[i + 3] = opacity(rng);
    }
    sparse = PackGrid<double>(bricks, std::span<const double>(dense).first(GridParamCount(n)));
    sparse.insert(sparse.end(), dense.begin() + GridParamCount(n), dense.end());

    dense_view.params = dense.data();
    dense_view.n = n;
    dense_view.size = box.size;
    dense_view.num_shells = 2;
    dense_view.m = m;
    dense_view.shell_center = MulMatTransposed(box.world_from_box, V3{0.1, 0.0, -0.1});
    dense_view.shell_radii[0] = 3.0;
    dense_view.shell_radii[1] = 6.0;
    sparse_view = dense_view;
    sparse_view.params = sparse.data();
    sparse_view.brick_slot = bricks.slot.data();
    sparse_view.skip_blocks = bricks.skip_blocks.data();
    sparse_view.active_bricks = bricks.ActiveBricks();
  }

  // The dense index of sparse grid parameter p (p < bricks.GridParams()).
  int64_t DenseIndexOf(int64_t p) const {
    const int64_t cell = p / 4, slot = cell / kBrickCells, local = cell % kBrickCells;
    const int64_t brick = bricks.bricks[slot];
    const int nb = bricks.nb(), n = bricks.n;
    const int i = static_cast<int>(brick % nb) * kBrickSide + static_cast<int>(local % kBrickSide);
    const int j = static_cast<int>(brick / nb % nb) * kBrickSide + static_cast<int>(local / kBrickSide % kBrickSide);
    const int k = static_cast<int>(brick / (int64_t{nb} * nb)) * kBrickSide + static_cast<int>(local / (kBrickSide * kBrickSide));
    return GridParam(GridCell(n, i, j, k), static_cast<int>(p % 4));
  }
};

BoxRay<double> RandomRay(const SparseScene& s, std::mt19937& rng, double distance) {
  return test::RandomCameraRay(s.box, s.dense_view.n, rng, distance, 0.4);
}

// J^T u for the 4 residual rows (u = the residuals), summed over rays.
struct Gradient {
  std::vector<double> g[4];
  explicit Gradient(size_t n) {
    for (auto& v : g) v.assign(n, 0.0);
  }
  const double* r = nullptr;
  void operator()(int64_t i, double a, double b, double c, double d) {
    g[0][i] += a * r[0];
    g[1][i] += b * r[1];
    g[2][i] += c * r[2];
    g[3][i] += d * r[3];
  }
};

// The brick grid of n^3 cells whose only active bricks are `p` and `q`.
BrickGrid TwoActiveBricks(int n, std::array<int, 3> p, std::array<int, 3> q) {
  const int nb = n / kBrickSide;
  std::vector<uint8_t> active(static_cast<size_t>(nb) * nb * nb, 0);
  active[BrickOf(nb, p[0], p[1], p[2])] = 1;
  active[BrickOf(nb, q[0], q[1], q[2])] = 1;
  return MakeBrickGrid(n, active);
}

// The empty-space table by its definition (ray_types.h SkipBlockOf), cell by cell: a block of an
// active brick is stored; one any of whose samples' cells (within half a cell of the block) is
// stored is reading; any other holds 1 + its chessboard distance to the nearest of those.
std::vector<uint8_t> WantSkipBlocks(const BrickGrid& b) {
  const int n = b.n, nk = n / kSkipBlockSide;
  std::vector<int> kind(static_cast<size_t>(nk) * nk * nk);  // 0 stored, 1 reading, 2 neither
  for (int k = 0; k < nk; ++k)
    for (int j = 0; j < nk; ++j)
      for (int i = 0; i < nk; ++i) {
        const int s = kSkipBlockSide;
        int& out = kind[(static_cast<size_t>(k) * nk + j) * nk + i];
        out = SparseCell(b.slot.data(), b.nb(), s * i, s * j, s * k) >= 0 ? 0 : 2;
        for (int z = s * k - 1; z <= s * k + s && out == 2; ++z)
          for (int y = s * j - 1; y <= s * j + s && out == 2; ++y)
            for (int x = s * i - 1; x <= s * i + s && out == 2; ++x)
              if (x >= 0 && y >= 0 && z >= 0 && x < n && y < n && z < n &&
                  SparseCell(b.slot.data(), b.nb(), x, y, z) >= 0) {
                out = 1;
              }
      }
  std::vector<uint8_t> want(kind.size());
  for (int k = 0; k < nk; ++k)
    for (int j = 0; j < nk; ++j)
      for (int i = 0; i < nk; ++i) {
        const size_t idx = (static_cast<size_t>(k) * nk + j) * nk + i;
        if (kind[idx] < 2) {
          want[idx] = kind[idx] == 0 ? kStoredBlock : kReadingBlock;
          continue;
        }
        int d = 1 << 20;
        for (int z = 0; z < nk; ++z)
          for (int y = 0; y < nk; ++y)
            for (int x = 0; x < nk; ++x)
              if (kind[(static_cast<size_t>(z) * nk + y) * nk + x] < 2) {
                d = std::min(d, std::max({std::abs(x - i), std::abs(y - j), std::abs(z - k)}));
              }
        want[idx] = static_cast<uint8_t>(std::min(1 + d, int{kMaxBlockValue}));
      }
  return want;
}

TEST(BrickGrid, SlotsMarksAndLayouts) {
  const int n = 32, nb = 4;
  const BrickGrid b = TwoActiveBricks(n, {1, 1, 1}, {3, 0, 0});
  ASSERT_EQ(b.ActiveBricks(), 2);
  EXPECT_EQ(b.slot[BrickOf(nb, 3, 0, 0)], 0);  // brick order, x fastest
  EXPECT_EQ(b.slot[BrickOf(nb, 1, 1, 1)], 1);
  EXPECT_EQ(b.bricks, (std::vector<int64_t>{BrickOf(nb, 3, 0, 0), BrickOf(nb, 1, 1, 1)}));
  EXPECT_EQ(b.skip_blocks, WantSkipBlocks(b));
  EXPECT_EQ(b.skip_blocks[SkipBlockOf(n, 8, 8, 8)], kStoredBlock);
  EXPECT_EQ(b.skip_blocks[SkipBlockOf(n, 6, 8, 8)], kReadingBlock);  // next to brick (1, 1, 1)
  EXPECT_EQ(b.skip_blocks[SkipBlockOf(n, 4, 8, 8)], 2);              // one block further

  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<float> dense(GridParamCount(n));
  for (float& v : dense) v = u(rng);
  const std::vector<float> packed = PackGrid<float>(b, dense);
  ASSERT_EQ(static_cast<int64_t>(packed.size()), 2 * kBrickCells * 4);
  const std::vector<float> back = UnpackGrid<float>(b, packed);
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const bool stored = b.slot[BrickOf(nb, i / 8, j / 8, k / 8)] >= 0;
        for (int ch = 0; ch < 4; ++ch) {
          const int64_t p = GridParam(GridCell(n, i, j, k), ch);
          ASSERT_EQ(back[p], stored ? dense[p] : 0.f) << i << " " << j << " " << k;
        }
      }
    }
  }
  // Every brick active: the same values, brick by brick.
  const BrickGrid full = MakeBrickGrid(16, std::vector<uint8_t>(8, 1));
  EXPECT_EQ(full.ActiveBricks(), 8);
  std::vector<float> small(GridParamCount(16));
  for (float& v : small) v = u(rng);
  EXPECT_EQ(UnpackGrid<float>(full, PackGrid<float>(full, small)), small);

  EXPECT_THROW(MakeBrickGrid(12, std::vector<uint8_t>(1, 1)), InputError);
  EXPECT_THROW(MakeBrickGrid(16, std::vector<uint8_t>(7, 1)), InputError);
}

// Active bricks in a ball around the centre plus a few lone ones: most of the box is skippable.
std::vector<uint8_t> BallOfBricks(int nb, std::mt19937& rng) {
  std::vector<uint8_t> active(static_cast<size_t>(nb) * nb * nb, 0);
  const double c = (nb - 1) / 2.0;
  for (int k = 0; k < nb; ++k)
    for (int j = 0; j < nb; ++j)
      for (int i = 0; i < nb; ++i) {
        const double d = std::hypot(i - c, j - c, k - c);
        active[BrickOf(nb, i, j, k)] = d < nb / 5.0;
      }
  std::uniform_int_distribution<int> any(0, nb - 1);
  for (int q = 0; q < 4; ++q) active[BrickOf(nb, any(rng), any(rng), any(rng))] = 1;
  return active;
}

// The empty-space table on a grid with two active bricks far apart, and the meaning of its marks:
// no sample in a block marked neither stored nor reading reaches a stored cell.
TEST(BrickGrid, SkipBlocksHoldTheDistanceToWhereASampleMayReadAStoredCell) {
  const int n = 80;
  const BrickGrid b = TwoActiveBricks(n, {1, 2, 1}, {6, 6, 7});
  EXPECT_EQ(b.skip_blocks, WantSkipBlocks(b));
  // Corners such as (39, 0, 0) lie 27 blocks from the nearest reading block.
  EXPECT_EQ(*std::max_element(b.skip_blocks.begin(), b.skip_blocks.end()), 1 + 27);
  VolumeView<double> vol{};
  vol.n = n;
  vol.brick_slot = b.slot.data();
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(0.0, n);
  int reading = 0, reached = 0, empty = 0;
  for (int t = 0; t < 200000; ++t) {
    const Vec3<double> g{u(rng), u(rng), u(rng)};
    const int v = b.skip_blocks[SkipBlockOf(n, static_cast<int>(g.x), static_cast<int>(g.y), static_cast<int>(g.z))];
    const bool reaches = ReachesStoredCell(vol, g);
    if (v == kStoredBlock) {
      ASSERT_TRUE(reaches);
    } else if (v == kReadingBlock) {
      reading++;
      reached += reaches;
    } else {
      empty++;
      ASSERT_FALSE(reaches) << g.x << " " << g.y << " " << g.z;
    }
  }
  EXPECT_GT(reached, reading / 10);  // a reading block's samples near the brick do read it
  EXPECT_GT(empty, 150000);
  // Nothing stored: every block at the cap.
  const BrickGrid none = MakeBrickGrid(16, std::vector<uint8_t>(8, 0));
  EXPECT_EQ(none.skip_blocks, std::vector<uint8_t>(512, kMaxBlockValue));
}

TEST(SparseMarch, EqualsTheDenseMarchWhereTheSkippedSpaceIsEmpty) {
  std::mt19937 rng(11);
  const int n = 96;
  SparseScene s(rng, n, BallOfBricks(n / kBrickSide, rng), 40.0);
  int wide = 0;  // blocks whose cube reaches beyond their neighbours: the march jumps several
  for (const uint8_t v : s.bricks.skip_blocks) wide += v >= 1 + 3;
  EXPECT_GT(wide, 10000);
  int skipping = 0;
  int64_t dense_samples = 0, sparse_samples = 0;
  const double target[3] = {0.2, 0.5, 0.7};
  for (const double stop : {0.0, 0.02}) {
    Gradient gd(s.dense.size()), gs(s.sparse.size()), gr(s.sparse.size());
    std::vector<SampleRecord<double>> record(4 * n);
    for (int r = 0; r < 300; ++r) {
      const BoxRay<double> ray = RandomRay(s, rng, r % 10 == 0 ? 0.3 : 2.5);  // some start inside the box
      const Jitter jit{99u, static_cast<uint32_t>(r), true, true};
      const double alpha = r % 2 ? 0.4 : -1.0;
      const RayOutput<double> d = Forward(s.dense_view, ray, jit, target, 0.1, stop, nullptr, alpha);
      const RayOutput<double> p = Forward(s.sparse_view, ray, jit, target, 0.1, stop, nullptr, alpha);
      for (int c = 0; c < 3; ++c) ASSERT_EQ(p.h[c], d.h[c]) << "ray " << r;
      for (int c = 0; c < 4; ++c) ASSERT_EQ(p.residual[c], d.residual[c]) << "ray " << r;
      ASSERT_EQ(p.t_box, d.t_box);
      ASSERT_EQ(p.depth, d.depth);
      ASSERT_EQ(p.end, d.end);
      ASSERT_LE(p.count, d.count);
      skipping += p.count < d.count;
      dense_samples += d.count;
      sparse_samples += p.count;

      gd.r = d.residual;
      BackwardPerParam(s.dense_view, ray, jit, d, gd);
      gs.r = p.residual;
      BackwardPerParam(s.sparse_view, ray, jit, p, gs);
      // With the record Forward keeps (the CPU backend's path).
      const RayOutput<double> pr = Forward(s.sparse_view, ray, jit, target, 0.1, stop, record.data(), alpha);
      ASSERT_EQ(pr.count, p.count);
      gr.r = pr.residual;
      PerParamVisitor<double, Gradient> visit{gr};
      Backward(s.sparse_view, ray, jit, pr, visit, record.data());
    }
    // J^T r on every stored parameter: the same sums in the same order.
    const int64_t grid = s.bricks.GridParams();
    for (int row = 0; row < 4; ++row) {
      for (int64_t i = 0; i < static_cast<int64_t>(s.sparse.size()); ++i) {
        const int64_t di = i < grid ? s.DenseIndexOf(i) : GridParamCount(n) + (i - grid);
        ASSERT_EQ(gs.g[row][i], gd.g[row][di]) << "row " << row << " param " << i << " stop " << stop;
        // The record keeps T_i as Forward's running product, the recomputation takes exp(-D_i).
        ASSERT_NEAR(gr.g[row][i], gs.g[row][i], 1e-12 + 1e-9 * std::abs(gs.g[row][i])) << "row " << row << " param " << i;
      }
    }
  }
  std::printf("sparse march: %lld of %lld dense samples taken (%.0f %%), %d of 600 rays skipped some\n",
              static_cast<long long>(sparse_samples), static_cast<long long>(dense_samples),
              100.0 * sparse_samples / dense_samples, skipping);
  EXPECT_GT(skipping, 300);
  EXPECT_LT(sparse_samples, dense_samples * 3 / 4);
}

TEST(SparseMarch, EveryPartialMatchesCentralDifferences) {
  std::mt19937 rng(5);
  const int n = 16, nb = 2;
  std::vector<uint8_t> active(nb * nb * nb, 0);
  active[BrickOf(nb, 0, 0, 0)] = active[BrickOf(nb, 1, 1, 0)] = active[BrickOf(nb, 1, 0, 1)] = 1;
  SparseScene s(rng, n, active, 6.0);
  const double target[3] = {0.2, 0.5, 0.7};
  const double lambda = 0.1, h = 1e-5;
  int checked = 0;
  for (int r = 0; r < 6; ++r) {
    const BoxRay<double> ray = RandomRay(s, rng, 2.5);
    const Jitter jit{7u, static_cast<uint32_t>(r), true, true};
    const RayOutput<double> out = Forward(s.sparse_view, ray, jit, target, lambda, 0.0, nullptr, -1.0);
    std::vector<double> j[4];
    for (auto& v : j) v.assign(s.sparse.size(), 0.0);
    auto row = [&](int64_t i, double a, double b, double c, double d) {
      j[0][i] += a;
      j[1][i] += b;
      j[2][i] += c;
      j[3][i] += d;
    };
    BackwardPerParam(s.sparse_view, ray, jit, out, row);
    for (size_t p = 0; p < s.sparse.size(); ++p) {
      const double keep = s.sparse[p];
      s.sparse[p] = keep + h;
      const RayOutput<double> plus = Forward(s.sparse_view, ray, jit, target, lambda, 0.0, nullptr, -1.0);
      s.sparse[p] = keep - h;
      const RayOutput<double> minus = Forward(s.sparse_view, ray, jit, target, lambda, 0.0, nullptr, -1.0);
      s.sparse[p] = keep;
      for (int c = 0; c < 4; ++c) {
        const double fd = (plus.residual[c] - minus.residual[c]) / (2 * h);
        ASSERT_NEAR(j[c][p], fd, 1e-7 + 1e-6 * std::abs(fd)) << "ray " << r << " param " << p << " res " << c;
        checked += std::abs(fd) > 1e-4;
      }
    }
  }
  EXPECT_GT(checked, 500);  // the rays cross stored bricks
}

}  // namespace
}  // namespace perf::recon
