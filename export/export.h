// `perf export WORKSPACE` (DESIGN.md "Export"): from the last checkpoint (or a given one),
//   masks/soft/<name>.png     soft foreground mask (16-bit PNG, or EXR) of every input photo,
//   masks/binary/<name>.png   the mask thresholded (0.7 by default, the paper's rule), 8-bit,
//                             both at the photo's size on disk and in its own (distorted) frame;
//   foreground/<name>.png     the photo with the mask as alpha (RGBA);
//   volume.vdb                density + colour grids (vdb_export.h);
//   mesh.ply                  the iso-surface with vertex colours (mesh_export.h, mesh_iso.h);
//   mesh.obj, mesh.mtl, mesh.png, mesh.glb  the same with a baked colour texture (mesh_texture.h;
//                             the GLB embeds it);
//   renders/test/<name>.png   held-out views, renders/orbit/frame_<k>.png an orbit of the box;
//   export.json               what was written, with sizes and settings.
// <name> is the workspace image's path under images/ without its extension (the photo's name).
// Every file is written atomically; the output folders are checked to be writable first.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "export/masks.h"
#include "export/mesh_export.h"
#include "export/mesh_iso.h"
#include "export/orbit.h"
#include "export/refined_model.h"
#include "export/vdb_export.h"
#include "recon_cuda/backends/make_backend.h"
#include "recon_cuda/core/render_rule.h"

namespace perf::exporter {

struct ExportOptions {
  std::filesystem::path workspace;
  std::filesystem::path checkpoint;  // empty: the final one (recon::FinalCheckpointPath)
  // What to write.
  bool masks = true, foreground = true, volume = true, mesh = true, renders = true;
  double mask_threshold = 0.7;  // binary mask: soft >= threshold
  bool soft_mask_exr = false;   // soft masks as float EXR instead of 16-bit PNG
  bool foreground_soft_alpha = false;  // cut-outs with the soft mask as alpha (default binary)
  MaskOptions mask;
  VdbOptions vdb;
  MeshOptions mesh_options;
  // The mesh's iso level chosen by its silhouettes against the masks (mesh_iso.h); false: at
  // mesh_options.iso_opacity (--iso 0.3). Default: chosen (--iso auto).
  bool auto_iso = true;
  // The mesh simplified to at most this many triangles (mesh_simplify.h); 0: as extracted.
  int64_t mesh_triangles = 200000;
  OrbitOptions orbit;           // frames = 0: no orbit
  float min_box_opacity = recon::kDefaultMinBoxOpacity; // renders: the render rule (render_rule.h)
  recon::DeviceChoice device = recon::DeviceChoice::kAuto;
  int threads = 0;
  // Called as work proceeds: step ("masks", "volume", "mesh", "renders"), done, total.
  std::function<void(const std::string& step, int done, int total)> progress;
};

struct ExportResult {
  std::filesystem::path checkpoint;
  int masks = 0, foreground = 0, renders = 0, orbit_frames = 0;
  double orbit_arc_degrees = 360;  // the orbit's sweep (orbit.h CapturedArc)
  double mean_mask_coverage = 0;  // mean fraction of photo pixels in the binary mask
  std::vector<std::string> no_mask;  // photos left out on import (a pose that looks wrong): no mask
  VdbStats vdb;
  int64_t mesh_vertices = 0, mesh_triangles = 0;
  int mesh_components_found = 0, mesh_components_kept = 0;
  IsoChoice iso;  // the mesh's level, its silhouettes' IoU, and a warning when it is empty
  int64_t mesh_triangles_extracted = 0;  // before simplification
  std::array<int, 2> texture_size{0, 0};  // mesh.png (0: no texture, an empty mesh)
  RefinedModel refined_model;  // WORKSPACE/sparse_refined (refined_model.h), with --refine-poses
  std::vector<std::filesystem::path> files;  // relative to the workspace
  double seconds = 0;
};

ExportResult RunExport(const ExportOptions& options);

// Seconds RunExport with `options` and then RunEval will take for `scene` (its cameras as the
// volume has them) from the volume `backend` holds at `params`, measured by doing one photo's
// work: its mask rendered and its mask files and cut-out written (to WORKSPACE/.perf/probe,
// removed after), times the photos; the held-out and orbit renders and eval's scores from that
// photo's render at the workspace's size, by their pixels. For perf run --time-budget.
// pose_fit: eval fits the held-out cameras too (the volume refines poses).
double EstimateExportAndEvalSeconds(recon::Backend* backend, recon::VecId params, const Scene& scene,
                                    const ExportOptions& options, bool pose_fit);

// The <name> above for a scene image.
std::filesystem::path OutputName(const SceneImage& image);

}  // namespace perf::exporter
