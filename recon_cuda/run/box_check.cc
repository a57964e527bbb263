#include "recon_cuda/run/box_check.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "workspace/scene.h"

namespace perf::recon {

std::vector<BoxFace> BoxFaces(const VolumeShape& shape, const VolumeGeometry& geometry, std::span<const float> x) {
  static const char* kNames[6] = {"-x", "+x", "-y", "+y", "-z (bottom)", "+z (top)"};
  const int n = shape.n;
  const float size[3] = {geometry.box.size.x, geometry.box.size.y, geometry.box.size.z};
  std::vector<BoxFace> faces(6);
  for (int f = 0; f < 6; ++f) {
    const int axis = f / 2, layer = f % 2 == 0 ? 0 : n - 1;
    const double h = static_cast<double>(size[axis]) / n;
    int64_t opaque = 0;
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        int ijk[3];
        ijk[axis] = layer;
        ijk[(axis + 1) % 3] = a;
        ijk[(axis + 2) % 3] = b;
        const int64_t cell = StoredCell(shape, ijk[0], ijk[1], ijk[2]);
        if (cell < 0) continue;
        const double sigma = x[GridParam(cell, 3)];
        opaque += 1.0 - std::exp(-sigma * h) >= kOpaqueCell;
      }
    }
    faces[f] = {kNames[f], static_cast<double>(opaque) / (static_cast<double>(n) * n)};
  }
  return faces;
}

bool FogCanLookOpaque(double box_opacity, const VolumeGeometry& geometry, int n) {
  const float* s = &geometry.box.size.x;
  const double shortest = std::min({s[0], s[1], s[2]}), longest = std::max({s[0], s[1], s[2]});
  const double sigma_max = 2 * -std::log(1 - std::clamp(box_opacity, 0.0, 1 - 1e-12)) / shortest;
  return 1 - std::exp(-sigma_max * longest / n) >= kOpaqueCell;
}

std::vector<int> FacesToGrow(const std::vector<BoxFace>& faces) {
  std::vector<int> grow;
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    if (f != 4 && faces[f].opaque_fraction >= kCutOffFraction) grow.push_back(f);  // 4: -z, the bottom
  }
  return grow;
}

VolumePlacement GrownPlacement(const VolumePlacement& p, const std::vector<int>& faces) {
  VolumePlacement g = p;
  for (int f : faces) {
    PERF_CHECK(f >= 0 && f < 6);
    const int axis = f / 2;
    const double sign = f % 2 == 0 ? -1.0 : 1.0;
    const double step = kGrowFraction * p.box_size[axis];
    g.box_size[axis] += step;
    // The centre moves half the step toward the face, along the box's axis in the world
    // (column `axis` of world_from_box, row-major).
    for (int r = 0; r < 3; ++r) g.box_center[r] += 0.5 * step * sign * p.box_rotation[3 * r + axis];
  }
  return g;
}

std::string CutOffWarning(const std::vector<BoxFace>& faces) {
  std::string list;
  int count = 0;
  for (const BoxFace& f : faces) {
    if (f.name.rfind("-z", 0) == 0 || f.opaque_fraction < kCutOffFraction) continue;
    list += StrCat(list.empty() ? "" : ", ", f.name, " (", std::lround(100 * f.opaque_fraction), " % opaque)");
    ++count;
  }
  if (list.empty()) return {};
  return StrCat("the fitted density reaches the box's ", list, count > 1 ? " faces" : " face",
                ": the object may go on beyond the box there and its masks would miss that part; check "
                "preview/box_*.png (perf import --preview-box) and re-import with a larger --box-size if so");
}

BoxGrowth GrowBox(Scene* scene, const std::vector<BoxFace>& faces, const std::vector<int>& grow) {
  BoxGrowth g;
  for (int f : grow) {
    const BoxFace& face = faces.at(static_cast<size_t>(f));
    g.names += StrCat(g.names.empty() ? "" : ", ", face.name);
    g.described += StrCat(g.described.empty() ? "" : ", ", face.name, " (", std::lround(100 * face.opaque_fraction),
                          " % opaque)");
  }
  g.face_count = static_cast<int>(grow.size());
  g.grown = GrownPlacement(VolumePlacement::FromScene(*scene), grow);
  for (int a = 0; a < 3; ++a) {
    scene->box.center[a] = g.grown.box_center[a];
    scene->box.size[a] = g.grown.box_size[a];
  }
  scene->box.method += StrCat("; grown by perf reconstruct at ", g.names);
  return g;
}

nlohmann::json BoxGrowth::ToJson() const {
  return {{"faces", names},
          {"size", {grown.box_size[0], grown.box_size[1], grown.box_size[2]}},
          {"center", {grown.box_center[0], grown.box_center[1], grown.box_center[2]}}};
}

std::string BoxGrowth::Message() const {
  return StrCat("the fitted density reaches the box's ", described, face_count > 1 ? " faces" : " face",
                ": the object goes on there; the box grows ", std::lround(100 * kGrowFraction), " % there, to ",
                grown.box_size[0], " x ", grown.box_size[1], " x ", grown.box_size[2],
                " (scene.json), and level 1 is fitted again");
}

}  // namespace perf::recon
