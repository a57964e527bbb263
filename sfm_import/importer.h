// `perf import`: a COLMAP sparse model (binary or text) or a NeRF transforms.json becomes a
// workspace the reconstruction can trust: undistorted pinhole images (optionally downscaled),
// a train/test split, the box and shells, all described by scene.json.
//
// Workspace layout written here:
//   scene.json            the scene (workspace/scene.h, docs/scene-json.md), written last
//   images/<name>.<ext>   undistorted, downscaled photos (PNG 8/16-bit, EXR for float sources)
//   alpha/<name>.png      the source alpha, when the photos had one (NeRF-synthetic)
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "sfm_import/bounds.h"
#include "workspace/scene.h"

namespace perf {

struct ImportOptions {
  // Exactly one source: a COLMAP model folder (with `images`), or a NeRF transforms.json.
  std::filesystem::path colmap_dir;
  std::filesystem::path images_dir;  // default for COLMAP: <model>/../../images
  std::filesystem::path nerf_json;
  std::filesystem::path workspace;

  int downscale = 1;  // integer factor (1: full resolution)
  int max_size = 0;   // alternatively: the target long side in pixels (0: unused)
  int holdout = 8;    // every N-th image is held out for testing (COLMAP: by name; NeRF: json order); 0: none
  bool skip_missing = false;  // import the others when model images are missing on disk
  // COLMAP photos whose pose looks wrong (bad_poses.h) are imported but marked "excluded" in
  // scene.json, out of training and scoring; true keeps them as train/test like the others.
  bool keep_bad_poses = false;
  Eigen::Vector3d background = Eigen::Vector3d::Ones();  // RGBA photos are composited over it
  // COLMAP: groups of photos whose turn about the object is not known (RepairResult::TurnUnknown),
  // marked in scene.json for perf reconstruct to search (ghost_move.h MarkTurnUnknown).
  std::vector<std::vector<std::string>> turn_unknown;

  // Overrides of the automatic placement (bounds.h).
  std::optional<Eigen::Vector3d> box_center, box_size;
  bool box_axis_aligned = false;  // keep the world axes instead of aligning to the cameras' up
  std::optional<std::vector<double>> shell_radii;
  BoundsOptions bounds;

  int num_threads = 0;  // 0: all cores
  std::function<void(int done, int total)> progress;

  // Throws InputError (file "command line") naming the bad option.
  void Check() const;
};

struct ImportResult {
  Scene scene;
  BoundsResult bounds;
  std::vector<std::string> warnings;
  double seconds = 0;
};

ImportResult RunImport(const ImportOptions& options);

// The photos of a COLMAP model given without --images: <model>/../../images (a COLMAP project's
// layout, project/sparse/0 beside project/images).
std::filesystem::path DefaultColmapImages(const std::filesystem::path& model_dir);

// A few lines for the terminal: images, cameras, box, shells.
std::string ImportSummary(const ImportResult& result);

}  // namespace perf
