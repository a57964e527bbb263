// Occupancy between levels (DESIGN.md "Hierarchy"): after a level is fitted, the next
// level stores only the bricks near cells that hold something, so that its cost follows the
// occupied space instead of the box volume.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "recon_cuda/data/volume.h"

namespace perf::recon {

struct OccupancyOptions {
  // A fitted cell is occupied when its opacity across one cell, 1 - exp(-sigma * cell side),
  // reaches this: low enough to keep faint structure, and the sparse level then scores about
  // as the dense one held-out (docs/tuning.md "Sparse levels").
  float min_opacity = 0.1f;
  // Occupied cells grow by this many cells of the fitted level before bricks are chosen, so that
  // surfaces can still move and trilinear samples near them keep real neighbours.
  int dilation = 1;
};

// Per brick of an n^3 grid (BrickOf order): 1 where some photo's rays may cross it, tested
// conservatively (the brick's bounding sphere in front of the camera and overlapping the image);
// 0 where none can, so that the solve cannot have fitted anything there.
std::vector<uint8_t> SeenBricks(int n, const VolumeGeometry& geometry, std::span<const ViewFrustum> views);

// The bricks of an n_next^3 grid (a multiple of 8) that cover the occupied cells of the fitted
// level (shape, x), dilated, and that some training photo sees (SeenBricks; no views: every brick).
std::shared_ptr<const BrickGrid> OccupiedBricks(const VolumeShape& shape, const VolumeGeometry& geometry,
                                                std::span<const float> x, int n_next, const OccupancyOptions& options,
                                                std::span<const ViewFrustum> views = {});

}  // namespace perf::recon
