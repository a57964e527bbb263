#include "export/mesh_simplify.h"

#include <meshoptimizer.h>

#include <vector>

namespace perf::exporter {

SimplifyResult SimplifyMesh(Mesh* mesh, int64_t target_triangles) {
  SimplifyResult r;
  r.triangles_before = r.triangles_after = static_cast<int64_t>(mesh->triangles.size());
  if (target_triangles <= 0 || r.triangles_before <= target_triangles) return r;
  std::vector<unsigned int> indices;
  indices.reserve(mesh->triangles.size() * 3);
  for (const auto& t : mesh->triangles) indices.insert(indices.end(), t.begin(), t.end());
  std::vector<unsigned int> kept(indices.size());
  size_t count = 0;
  for (const float error : {0.01f, 0.05f}) {
    count = meshopt_simplify(kept.data(), indices.data(), indices.size(), mesh->positions.front().data(),
                             mesh->positions.size(), sizeof(mesh->positions.front()),
                             static_cast<size_t>(target_triangles) * 3, error, 0, nullptr);
    r.error = error;
    if (static_cast<int64_t>(count / 3) <= target_triangles) break;
  }
  // The vertices still used, renumbered in their old order, with their colours.
  std::vector<int64_t> renumber(mesh->positions.size(), -1);
  Mesh out;
  out.components_found = mesh->components_found;
  out.components_kept = mesh->components_kept;
  for (size_t i = 0; i < count; i += 3) {
    std::array<uint32_t, 3> t{};
    for (int k = 0; k < 3; ++k) {
      const unsigned int v = kept[i + static_cast<size_t>(k)];
      if (renumber[v] < 0) {
        renumber[v] = static_cast<int64_t>(out.positions.size());
        out.positions.push_back(mesh->positions[v]);
        out.colours.push_back(mesh->colours[v]);
      }
      t[static_cast<size_t>(k)] = static_cast<uint32_t>(renumber[v]);
    }
    out.triangles.push_back(t);
  }
  *mesh = std::move(out);
  r.triangles_after = static_cast<int64_t>(mesh->triangles.size());
  return r;
}

}  // namespace perf::exporter
