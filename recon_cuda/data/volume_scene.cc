// The parts of volume.h that read a Scene (scene.json): kept apart so that the solver, the
// backends and the GPU benchmark link without the importer's libraries.
#include "recon_cuda/data/volume.h"
#include "workspace/scene.h"

namespace perf::recon {

VolumePlacement VolumePlacement::FromScene(const Scene& scene) {
  VolumePlacement p;
  for (int a = 0; a < 3; ++a) {
    p.box_center[a] = scene.box.center[a];
    p.box_size[a] = scene.box.size[a];
    p.shell_center[a] = scene.shells.center[a];
  }
  for (int i = 0; i < 9; ++i) p.box_rotation[i] = scene.box.rotation(i / 3, i % 3);
  p.shell_radii = scene.shells.radii;
  return p;
}

VolumeGeometry VolumeGeometry::FromScene(const Scene& scene) {
  return From(VolumePlacement::FromScene(scene), "scene.json");
}

}  // namespace perf::recon
