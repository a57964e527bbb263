// Does the box hold the whole object? After the first level, opaque cells in the
// outermost layer of a box face mean the fitted density goes on beyond that face: the object (or
// what it stands on) is cut off there, and its masks will miss that part. The bottom face (-z,
// the box is aligned to the cameras' up) is where the object stands and is left out of the
// warning (a table or floor always reaches it).
#pragma once

#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "recon_cuda/data/volume.h"

namespace perf {
struct Scene;
}

namespace perf::recon {

struct BoxFace {
  std::string name;             // "+x", "-x", "+y", "-y", "+z (top)", "-z (bottom)"
  double opaque_fraction = 0;   // of the face's outermost cells, those at least kOpaqueCell opaque
};

// A cell is opaque when 1 - exp(-sigma h) reaches this (h: the cell's side along the face normal).
inline constexpr double kOpaqueCell = 0.5;
// The warning's threshold on a side or top face's opaque fraction.
inline constexpr double kCutOffFraction = 0.05;

// The six faces of the grid of (shape, x); a sparse grid's inactive cells count as empty.
std::vector<BoxFace> BoxFaces(const VolumeShape& shape, const VolumeGeometry& geometry, std::span<const float> x);

// One line naming the side and top faces at or above kCutOffFraction and what to do, or "" when
// none is.
std::string CutOffWarning(const std::vector<BoxFace>& faces);

// Growing the box where the object goes on (perf reconstruct, ReconstructOptions::grow_box): each
// side or top face at or above kCutOffFraction moves out by kGrowFraction of the box's size along
// its axis (the opposite face stays), and level 0 is fitted again in the grown box, at most
// kMaxBoxGrowths times.
inline constexpr double kGrowFraction = 0.25;
inline constexpr int kMaxBoxGrowths = 2;

// Whether the first level's starting fog (InitOptions: box opacity `box_opacity` across the
// shortest side, each cell's sigma uniform in [0, 2 s]) can already make a cell of an n^3 grid
// kOpaqueCell opaque: then an opaque face says nothing about the object (at 8^3 from the default
// 0.99 a cell can reach 0.68), and the box is not grown from it.
bool FogCanLookOpaque(double box_opacity, const VolumeGeometry& geometry, int n);

// The faces (indices into BoxFaces' order: -x, +x, -y, +y, -z, +z) to move out; the bottom never.
std::vector<int> FacesToGrow(const std::vector<BoxFace>& faces);

// `placement` with `faces` moved out by kGrowFraction of the box along their axes, in the box's
// own frame (the shells stay where they are).
VolumePlacement GrownPlacement(const VolumePlacement& placement, const std::vector<int>& faces);

// One growth of the box: which faces moved and the box it made.
struct BoxGrowth {
  std::string names;      // "+x, +z (top)"
  std::string described;  // "+x (12 % opaque), +z (top) (7 % opaque)"
  int face_count = 0;
  VolumePlacement grown;
  // recon.json's and the log's: faces, size, center.
  nlohmann::json ToJson() const;
  // The line that tells the user (the box grows, scene.json, level 1 fitted again).
  std::string Message() const;
};

// Grows `scene`'s box at `grow` (FacesToGrow of `faces`) and notes it in the box's method;
// writing scene.json is the caller's.
BoxGrowth GrowBox(Scene* scene, const std::vector<BoxFace>& faces, const std::vector<int>& grow);

}  // namespace perf::recon
