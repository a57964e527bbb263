// OpenVDB export of a reconstruction (DESIGN.md "Export"): a `density` FloatGrid (sigma in 1 /
// world unit, grid class fog volume) and a `color` Vec3SGrid (linear RGB, converted from the
// solver's sRGB values), sparse (only cells whose opacity across one voxel reaches a
// threshold), with the box's placement in the world frame of the source (COLMAP or NeRF json)
// as the grids' transform. This is what Blender's Principled Volume reads; `houdini_names`
// names the colour grid `Cd`. OpenVDB is included only in the .cc (it is slow to compile).
//
// Index space: OpenVDB puts voxel centres at integer index coordinates, so voxel (i, j, k) is
// grid cell (i, j, k) of ray_types.h and the transform maps (i, j, k) to the cell centre
// world = box_center + world_from_box (((i, j, k) + 0.5) * box_size / n - box_size / 2):
// rotation, per-axis (anisotropic) scale and translation in one affine map.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>

#include "recon_cuda/data/checkpoint.h"

namespace perf::exporter {

struct VdbOptions {
  // A cell is written when its opacity across one voxel, 1 - exp(-sigma * CellLength), reaches
  // this; 0 writes every cell with sigma > 0.
  double min_cell_opacity = 0.01;
  bool houdini_names = false;  // colour grid named `Cd` instead of `color`
  bool half_float = false;     // store the grids as 16-bit floats
};

struct VdbStats {
  int64_t active_voxels = 0;  // written cells (the same in both grids)
  int64_t total_voxels = 0;   // n^3
  double voxel_size[3] = {0, 0, 0};  // world units along the box axes
  std::string density_grid, colour_grid;  // the grid names written
  // With view-dependent colour (--sh-degree): one grid per spherical-harmonic band beyond the
  // constant, "color_sh1" .. (the colour grid holds the constant term).
  std::vector<std::string> sh_grids;
  int64_t file_bytes = 0;
};

// Writes `path` atomically. Throws IoError naming the file when it cannot be written.
VdbStats WriteVdb(const recon::Checkpoint& checkpoint, const std::filesystem::path& path,
                  const VdbOptions& options);

// The length (world units) over which a cell's opacity 1 - exp(-sigma L) is measured by the VDB
// threshold and the mesh iso-level: the cell's shortest side, min(box_size) / n, which is the
// renderer's ray-march step (MakeMarch), so a cell's opacity here is that of one render sample.
double CellLength(const recon::Checkpoint& checkpoint);

// Index space (cell centres at integers) to world, 3x4 row-major: world = A (i, j, k, 1)^T.
std::array<double, 12> WorldFromIndex(const recon::Checkpoint& checkpoint);

// Throws InputError (file "checkpoint") unless the grid can be exported: n >= 1, the grid's
// parameters present, a positive finite box size.
void CheckExportable(const recon::Checkpoint& checkpoint);

// The sRGB EOTF (IEC 61966-2-1): encoded value in [0, 1] -> linear.
double SrgbToLinear(double encoded);

}  // namespace perf::exporter
