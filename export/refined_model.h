// WORKSPACE/sparse_refined: the imported COLMAP model with the cameras --refine-poses refined
// (issue 31), for COLMAP, perf import --colmap and every tool that reads a sparse model. The
// imported model is read, never written; its cameras (intrinsics), 2-D points and 3-D points are
// kept as they are; each training image takes its refined pose and each held-out image the pose
// its neighbours' corrections give it; an image left out on import keeps its imported pose.
#pragma once

#include <filesystem>
#include <string>

#include "workspace/scene.h"

namespace perf::exporter {

struct RefinedModel {
  std::filesystem::path dir;  // relative to the workspace; empty when not written
  int moved = 0;              // images whose pose was replaced
  std::string not_written;    // why there is none (not a COLMAP import, or nothing refined)
};

// `posed`: the scene as the checkpoint poses it (recon/render_views.h PosedAsCheckpoint).
// Writes WORKSPACE/sparse_refined/{cameras,images,points3D}.bin, each atomically (perf export
// passes its staging folder as WORKSPACE; an old set without refined cameras goes as stale there).
RefinedModel WriteRefinedModel(const Scene& posed, const std::filesystem::path& workspace);

}  // namespace perf::exporter
