// The mesh's iso level chosen for the capture, and the mesh judged by what the photos say: its
// silhouette in the training views against the masks' rule (the box opacity 1 - T_box at or
// above the mask threshold, rendered in the undistorted workspace frame at a reduced size). A
// fixed opacity per voxel suits a solid synthetic object (lego: 0.5) but not a real capture whose
// density regularisation and a coarser grid spread out (the bonsai example's mesh was empty at 0.5).
#pragma once

#include <string>
#include <vector>

#include <cstdint>
#include <nlohmann/json.hpp>

#include "export/mesh_export.h"
#include "recon_cuda/run/render_views.h"
#include "workspace/scene.h"

namespace perf::exporter {

// The training views' silhouettes by the masks' rule, at most `max_views` views evenly spread over
// the training photos, each at most `max_side` pixels on its longer side.
struct SilhouetteMask {
  int width = 0, height = 0;
  std::vector<uint8_t> inside;  // [height, width], 1 inside
};
struct Silhouettes {
  std::vector<recon::PinholeCamera<float>> cameras;  // scaled to the silhouettes' size
  std::vector<SilhouetteMask> masks;
};
Silhouettes RenderSilhouettes(recon::LoadedCheckpoint& loaded, const Scene& scene, double threshold,
                              int max_views = 8, int max_side = 128);

// The mean over the views (those where the mask or the mesh covers a pixel) of the IoU of the
// mesh's projected triangles with the mask; 0 for an empty mesh, -1 when no view counts.
double SilhouetteIou(const Mesh& mesh, const Silhouettes& views);

struct IsoCandidate {
  double iso = 0, iou = 0;
  int64_t triangles = 0;
};

struct IsoChoice {
  double iso = 0.5;
  bool automatic = false;            // chosen by silhouettes (else as given)
  double silhouette_iou = -1;        // of the chosen mesh (-1: no training view to judge by)
  std::vector<IsoCandidate> tried;   // automatic: every candidate, finest last
  std::string warning;               // non-empty: the mesh is empty, why, and what to try
  nlohmann::json ToJson() const;
};

// The iso levels an automatic choice tries, from the solid object's 0.5 down to faint fog.
std::vector<double> IsoLadder();

// The mesh at the iso level whose silhouettes match the masks best (ties: the higher level, the
// tighter surface); with `automatic` false, at options.iso_opacity. `mesh` gets it.
IsoChoice ChooseIsoAndMesh(const recon::Checkpoint& checkpoint, const MeshOptions& options, bool automatic,
                           const Silhouettes& views, Mesh* mesh);

}  // namespace perf::exporter
