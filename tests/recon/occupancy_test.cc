// Occupancy between levels (recon_cuda/data/occupancy.h): which bricks of the next level a fitted
// level keeps (occupied cells, dilated) and which no training photo can see (SeenBricks).
#include "recon_cuda/data/occupancy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "recon_cuda/data/brick_grid.h"

namespace perf::recon {
namespace {

VolumeGeometry UnitBox() {  // [-1, 1]^3, axis-aligned
  VolumeGeometry g;
  g.box.center = {0, 0, 0};
  g.box.world_from_box = {{1, 0, 0, 0, 1, 0, 0, 0, 1}};
  g.box.size = {2, 2, 2};
  g.shell_center = {0, 0, 0};
  g.shell_radii = {3};
  return g;
}

// A 16^3 grid, empty but for the cells given (sigma 100: opaque across one cell).
std::vector<float> WithCells(const VolumeShape& shape, const std::vector<std::array<int, 3>>& cells) {
  std::vector<float> x(static_cast<size_t>(shape.ParamCount()), 0.f);
  for (const auto& c : cells) x[GridParam(GridCell(shape.n, c[0], c[1], c[2]), 3)] = 100.f;
  return x;
}

std::vector<int64_t> Kept(const std::shared_ptr<const BrickGrid>& grid) { return grid->bricks; }

TEST(OccupancyTest, BricksCoverTheOccupiedCellsGrownByTheDilation) {
  const VolumeGeometry g = UnitBox();
  const VolumeShape shape{16, 4, 1};
  OccupancyOptions o;
  o.dilation = 1;
  // Fitted cell 5 is next cells 10-11; grown by one fitted cell, next cells 8-13: brick 1 alone.
  EXPECT_EQ(Kept(OccupiedBricks(shape, g, WithCells(shape, {{5, 5, 5}}), 32, o)),
            (std::vector<int64_t>{BrickOf(4, 1, 1, 1)}));
  // Fitted cell 4 grown: next cells 6-11, bricks 0 and 1 along each axis.
  EXPECT_EQ(OccupiedBricks(shape, g, WithCells(shape, {{4, 5, 5}}), 32, o)->ActiveBricks(), 2);
  EXPECT_EQ(OccupiedBricks(shape, g, WithCells(shape, {{4, 4, 4}}), 32, o)->ActiveBricks(), 8);
  o.dilation = 0;
  EXPECT_EQ(OccupiedBricks(shape, g, WithCells(shape, {{4, 4, 4}}), 32, o)->ActiveBricks(), 1);
  // Faint cells (opacity across a cell below min_opacity) are empty.
  std::vector<float> faint = WithCells(shape, {{4, 4, 4}});
  faint[GridParam(GridCell(16, 4, 4, 4), 3)] = 0.5f;  // 1 - exp(-0.5 * 2 / 16) = 0.06
  EXPECT_EQ(OccupiedBricks(shape, g, faint, 32, o)->ActiveBricks(), 0);
}

// A camera 10 units before the box looking along +z through a 4 x 4 pixel image with f = 100:
// about 0.2 units either side of the axis at the box.
ViewFrustum Narrow(float z) { return {{100, 100, 2, 2, {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, z}}, 4, 4}; }

TEST(OccupancyTest, BricksNoPhotoSeesAreLeftOut) {
  const VolumeGeometry g = UnitBox();
  const std::vector<ViewFrustum> views = {Narrow(-10)};
  const std::vector<uint8_t> seen = SeenBricks(32, g, views);  // 4 x 4 x 4 bricks of 0.5 units
  for (int bk = 0; bk < 4; ++bk) {
    for (int bj = 0; bj < 4; ++bj) {
      for (int bi = 0; bi < 4; ++bi) {
        const bool central = (bi == 1 || bi == 2) && (bj == 1 || bj == 2);
        EXPECT_EQ(seen[BrickOf(4, bi, bj, bk)], central) << bi << " " << bj << " " << bk;
      }
    }
  }
  // Conservative: every brick a ray of the photo passes through is seen.
  for (float px = 0; px <= 4; px += 0.25f) {
    for (float py = 0; py <= 4; py += 0.25f) {
      for (float t = 8; t <= 12; t += 0.01f) {
        const float x = (px - 2) / 100 * t, y = (py - 2) / 100 * t, z = -10 + t;
        if (std::abs(x) >= 1 || std::abs(y) >= 1 || std::abs(z) >= 1) continue;
        const int bi = static_cast<int>((x + 1) / 0.5f), bj = static_cast<int>((y + 1) / 0.5f),
                  bk = static_cast<int>((z + 1) / 0.5f);
        ASSERT_TRUE(seen[BrickOf(4, bi, bj, bk)]) << px << " " << py << " " << t;
      }
    }
  }
  // Facing away from the box (behind it is nothing), the photo sees no brick.
  std::vector<ViewFrustum> away = {Narrow(-10)};
  for (int i : {0, 5, 10}) away[0].camera.world_from_cam[i] = -1;  // R = diag(-1, -1, -1)
  for (uint8_t s : SeenBricks(32, g, away)) EXPECT_EQ(s, 0);
  // A camera inside the box sees the bricks around it whatever its image.
  EXPECT_TRUE(SeenBricks(32, g, std::vector<ViewFrustum>{Narrow(0.1f)})[BrickOf(4, 2, 2, 2)]);

  // Occupancy keeps only seen bricks: an occupied cell in a corner no photo sees is dropped.
  const VolumeShape shape{16, 4, 1};
  OccupancyOptions o;
  const std::vector<float> x = WithCells(shape, {{0, 0, 8}, {8, 8, 8}});
  EXPECT_EQ(OccupiedBricks(shape, g, x, 32, o)->ActiveBricks(), 2 + 8);
  const auto kept = OccupiedBricks(shape, g, x, 32, o, views);
  EXPECT_EQ(kept->ActiveBricks(), 4 * 2);  // the central 2 x 2 columns, the 2 layers around z = 0
  for (int64_t b : kept->bricks) EXPECT_TRUE(seen[b]);
}

}  // namespace
}  // namespace perf::recon
