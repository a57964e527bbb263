// Checkpoints of the reconstruction: one file per completed level, recon/level_<k>.perfvol,
// self-describing so that export and render need nothing else (the box and shells in world
// units travel with the values).
//
// Format (version 4, little-endian):
//   char[8]  magic "PERFVOL\0"
//   u32      version (4; versions 1, always dense, 2, without exposures, and 3, without poses, are
//            still read)
//   u32      header bytes (this fixed header: 288; version 3: 280; version 2: 272; version 1: 264)
//   i32      level, n, m, num_shells, iterations (GN iterations or Adam steps run at the level)
//   i32      solver (0 Gauss-Newton, 1 Adam)
//   f64[3]   box centre, f64[9] box rotation (world_from_box, row-major), f64[3] box size
//   f64[3]   shell centre (world), f64[8] shell radii (unused ones 0)
//   u64      parameter count (= VolumeShape::ParamCount)
//   u64      FNV-1a 64 of the brick list's bytes then the parameter bytes
//   i64      B: -1 for a dense grid, else the number of active bricks (not in version 1)
//   i32      photos whose exposures end the parameters (VolumeShape::exposures; from version 3)
//   i32      degree of the grid's spherical harmonics after the shells (0 to 2; from version 3)
//   i32      photos whose pose corrections follow the exposures (VolumeShape::poses; from version 4)
//   i32      0 (reserved; from version 4)
//   u32[B]   the active bricks' indices (ray_types.h BrickOf), ascending: their slot order
//   f32[count] parameters, layout of ray_types.h
// The reader checks every field and names the file and field on any mismatch, and checks the
// parameter count against the bytes the file holds before allocating; writes are atomic.
#pragma once

#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <vector>

#include "recon_cuda/data/volume.h"

namespace perf::recon {

// The finest grid PERF fits (reconstruct_options.cc; the GPU's default and the high preset's
// finest) and reads: 1024 cells across. A sparse level's tables follow from n alone (the march's
// skip table and its distances, 2 (n/2)^3 bytes: 256 MiB at 1024), so a header claiming more is
// refused before anything is allocated from it.
inline constexpr int kMaxGridSize = 1024;

inline constexpr uint32_t kCheckpointVersion = 4;

struct Checkpoint {
  int level = 0;
  int iterations = 0;
  int solver = 0;  // 0 Gauss-Newton, 1 Adam
  VolumeShape shape;
  VolumePlacement placement;  // as in scene.json when the checkpoint was written
  std::vector<float> params;
};

// Stream overloads; `name` is used in messages.
void WriteCheckpoint(std::ostream& out, const Checkpoint& c);
Checkpoint ReadCheckpoint(std::istream& in, const std::string& name);
// Path overloads: the writer is atomic; the reader throws IoError / InputError naming the file.
void WriteCheckpoint(const std::filesystem::path& path, const Checkpoint& c);
Checkpoint ReadCheckpoint(const std::filesystem::path& path);

// The geometry the checkpoint records (for MakeView).
inline VolumeGeometry GeometryOf(const Checkpoint& c) { return VolumeGeometry::From(c.placement, "checkpoint"); }

// recon/level_<k>.perfvol in a workspace.
std::filesystem::path CheckpointPath(const std::filesystem::path& workspace, int level);
// The highest level with a checkpoint file, or -1.
int LastCheckpointLevel(const std::filesystem::path& workspace);

}  // namespace perf::recon
