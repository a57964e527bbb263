// A colour texture for the mesh, so that DCC tools show its colours by default (Blender does not
// show vertex colours without a material set up for them) and a simplified mesh keeps the detail
// of the colour grid between its vertices. The atlas gives every triangle a square cell of its own
// (a right triangle in the cell's upper-left half, the rest of the cell filled with the colour of
// the triangle's nearest point, so that filtering at its edges never reads a neighbour's colour);
// each texel takes the colour grid's colour (ColourSampler) at its point on the triangle, or,
// where that point lies off the surface in empty cells (a simplified mesh's large triangle), the
// blend of the triangle's vertex colours.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <string>
#include <vector>

#include "export/mesh_export.h"

namespace perf::exporter {

struct TexturedMesh {
  Mesh mesh;
  // Per triangle corner (3 per triangle, in the triangles' order), glTF's convention: (0, 0) the
  // texture's top-left corner, v down.
  std::vector<std::array<float, 2>> uvs;
  int width = 0, height = 0;  // of the texture
  int cell = 0;               // texels per cell side
  std::vector<uint8_t> rgb;   // the texture, sRGB, 8 bits, row-major from the top row
};

// The texture at most `max_side` texels a side, cells of 4 to 32 texels a side.
TexturedMesh BakeTexture(const Mesh& mesh, const ColourSampler& colours, int max_side = 2048);

// The texture as PNG bytes.
std::string TexturePng(const TexturedMesh& textured);

// OBJ with `vt` texture coordinates (OBJ's v up), `mtllib <mtl_name>` and a material whose
// map_Kd is `png_name`; the vertex colours stay as `v x y z r g b`. MTL: the material.
void WriteTexturedObj(std::ostream& out, const TexturedMesh& textured, const std::string& mtl_name);
void WriteMtl(std::ostream& out, const std::string& png_name);

}  // namespace perf::exporter
