// A coloured triangle mesh of a reconstruction (DESIGN.md "Export"): the iso-surface of the
// opacity field by OpenVDB's volumeToMesh, vertex colours sampled from the colour grid, optional
// removal of small connected components (floaters), written as binary PLY, OBJ (vertex colours
// as the common `v x y z r g b` extension that Blender and MeshLab read) and glTF binary (.glb,
// COLOR_0 linear as glTF requires). Positions are in the world frame and units of the source.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <string>
#include <vector>

#include "recon_cuda/data/checkpoint.h"

namespace perf::exporter {

struct MeshOptions {
  // The surface is where a cell's opacity across one voxel, 1 - exp(-sigma * CellLength)
  // (vdb_export.h: the shortest side of a cell), interpolated between cell centres, crosses
  // this value. Outside the box counts as empty, so an object cut by the box wall is closed by
  // a cap at the wall (for iso_opacity >= 0.5 the cap never lies outside the box).
  double iso_opacity = 0.5;
  // Keep connected components with at least this fraction of the largest one's triangles
  // (1: only the largest; 0: all).
  double min_component_fraction = 0.05;
  double adaptivity = 0.0;  // volumeToMesh's adaptivity (0: uniform triangles)
};

struct Mesh {
  std::vector<std::array<float, 3>> positions;  // world
  // sRGB-encoded, [0, 1], per vertex: the trilinear interpolation of the cells' colours at the
  // vertex, each cell weighted by its opacity as well, so that the unconstrained colours of
  // empty cells (the solver never sees them) do not bleed into the surface.
  std::vector<std::array<float, 3>> colours;
  std::vector<std::array<uint32_t, 3>> triangles;  // counter-clockwise seen from outside
  int components_found = 0, components_kept = 0;
};

// The sRGB colour at world points by the vertex colours' rule (opacity-weighted trilinear over the
// cells), for textures baked at a finer spacing than the vertices (mesh_texture.h). `checkpoint`
// must outlive it.
class ColourSampler {
 public:
  explicit ColourSampler(const recon::Checkpoint& checkpoint);
  // near_opaque (optional): whether a cell around the point has opacity; where none has, the
  // colour is the cells' unweighted one, which no photo constrained.
  std::array<float, 3> At(const std::array<double, 3>& world, bool* near_opaque = nullptr) const;

 private:
  const recon::Checkpoint& checkpoint_;
  std::array<double, 12> index_from_world_;  // row-major 3x4
  double length_;
};

// Empty mesh (no error) when nothing reaches the iso value. Throws InputError when the
// checkpoint's grid is unusable (CheckExportable).
Mesh ExtractMesh(const recon::Checkpoint& checkpoint, const MeshOptions& options);

// Writers. The stream overloads leave failures in the stream's state; the path overloads are
// atomic and throw IoError naming the file.
// PLY: binary little-endian, float x y z, uchar red green blue (sRGB), int vertex_indices.
void WritePly(std::ostream& out, const Mesh& mesh);
void WritePly(const std::filesystem::path& path, const Mesh& mesh);
// OBJ: `v x y z r g b` (sRGB in [0, 1]) and 1-based `f a b c`; no material file.
void WriteObj(std::ostream& out, const Mesh& mesh);
void WriteObj(const std::filesystem::path& path, const Mesh& mesh);
// glTF 2.0 binary: one mesh (POSITION, COLOR_0 linear, UNSIGNED_INT indices) with a
// non-metallic material (glTF's default material is fully metallic), one node, one scene.
void WriteGlb(std::ostream& out, const Mesh& mesh);
void WriteGlb(const std::filesystem::path& path, const Mesh& mesh);
// glTF binary with a baked texture embedded (mesh_texture.h): a vertex per triangle corner with
// its TEXCOORD_0 (uvs: 3 per triangle, glTF's v down), the PNG as baseColorTexture, no COLOR_0
// (glTF would multiply the two). An empty mesh or texture: the vertex-colour GLB.
void WriteGlb(std::ostream& out, const Mesh& mesh, const std::vector<std::array<float, 2>>& uvs,
              const std::string& png);

// For tests and reports: surface area and enclosed volume (divergence theorem), world units.
double MeshArea(const Mesh& mesh);
double MeshVolume(const Mesh& mesh);

}  // namespace perf::exporter
