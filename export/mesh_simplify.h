// Lighter meshes for DCC tools and the web: meshoptimizer's edge-collapse simplifier (quadric
// error) brings a mesh down to a triangle budget where the surface allows it. The vertices kept
// keep their positions and colours (the simplifier moves none), so colours stay where they were.
#pragma once

#include <cstdint>

#include "export/mesh_export.h"

namespace perf::exporter {

struct SimplifyResult {
  int64_t triangles_before = 0, triangles_after = 0;
  double error = 0;  // the largest deviation allowed, relative to the mesh's extent
};

// At most `target_triangles` triangles (0: leave the mesh as it is), collapsing edges with an
// error of up to 1 % of the mesh's extent first and up to 5 % where that is not enough; a mesh
// already within the budget is left alone.
SimplifyResult SimplifyMesh(Mesh* mesh, int64_t target_triangles);

}  // namespace perf::exporter
