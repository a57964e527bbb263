// The coarse-to-fine hierarchy of DESIGN.md "Hierarchy", with no file I/O: `perf reconstruct`
// (reconstruct.h, the workspace adapter) and the GPU benchmark run this one loop. Level 0 starts
// from InitialParams at start_resolution^3; each level fits (a pyramid level of) the training
// photos for a fixed number of solver iterations and is interpolated into the next (every
// resolution doubled).
#pragma once

#include <array>
#include <functional>
#include <vector>

#include "recon_cuda/data/occupancy.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/data/volume.h"
#include "recon_cuda/solve/backend.h"
#include "recon_cuda/solve/solver.h"

namespace perf::recon {

struct HierarchyOptions {
  int levels = 2;
  int start_resolution = 32;  // grid cells per axis (and texels per face side) at level 0
  int iterations = 30;        // solver iterations per level (paper: 30)
  std::vector<int> level_iterations;  // level k runs level_iterations[k] where given, else `iterations`
  SolverOptions solver;       // max_iterations and seed are set per level
  InitOptions init;           // the start of level 0
  ResidualSettings residuals;
  // The robust loss (ResidualSettings::robust_scale) applies from this level on; the levels
  // before fit by least squares. From the fog of the start every ray's error is large, and a
  // robust loss there fits nothing (bonsai example, docs/tuning.md "Robust loss").
  int robust_from_level = 1;
  // The shells' texels per face side follow the grid (doubling per level) but stay coarse enough
  // that the level's rays number at least this many per texel of all shells (ShellResolution);
  // 0: the grid's ladder alone. 8 (the default): where the rays are few, coarser shells
  // generalise better held-out and keep the object's figure (docs/tuning.md "Shell resolution
  // from the rays").
  double min_rays_per_texel = 8;
  // Training photos whose exposures every level solves (VolumeShape::exposures); 0: none.
  int exposures = 0;
  // Spherical harmonics of the grid's colour (VolumeShape::sh_degree) at the levels from
  // sh_from_level on; the levels before fit a view-independent colour and the bands start at 0
  // (Resample). sh_degree 0: none.
  int sh_degree = 0;
  int sh_from_level = 0;
  // Training photos whose poses the levels from refine_poses_from on refine (VolumeShape::poses);
  // 0: none. The corrections carry over from level to level.
  int poses = 0;
  int refine_poses_from = 0;
  bool refine_focal = false;  // with poses: their focal lengths too (LevelProblem::fixed_focal)
  bool fixed_background = false;              // the shells are constants in `background`
  std::array<float, 3> background{1, 1, 1};  // (scene.json's background)
  bool pyramid = true;  // coarse levels fit downscaled photos (PyramidFactor)
  // Levels after the first store only the bricks near what the level before fitted (occupancy.h);
  // false keeps every level dense (--dense).
  bool sparse = true;
  OccupancyOptions occupancy;
  // A level after the first whose vectors and rays would not fit the backend's memory ends the
  // hierarchy at the level before (automatic levels); false: SetLevel throws ResourceError.
  bool stop_when_out_of_memory = false;

  int ShDegreeAt(int level) const { return level >= sh_from_level ? sh_degree : 0; }
  int IterationsAt(int level) const {
    return level < static_cast<int>(level_iterations.size()) ? level_iterations[level] : iterations;
  }
};

// Texels per face side for a level whose ladder gives `ladder` and that fits `rays` rays: the
// largest m <= ladder with rays >= min_rays_per_texel * 6 m^2 num_shells, but not below
// min(ladder, 8).
int ShellResolution(int ladder, int64_t rays, int num_shells, double min_rays_per_texel);

// The downscale of the training photos (`views`) that `level` of `o` fits with its n^3 grid:
// PyramidFactor, or 1 without the pyramid. The time plan counts each level's rays by it.
int LevelDownscale(const HierarchyOptions& o, std::span<const ViewFrustum> views, const VolumeGeometry& geometry, int n,
                   int level);

// The resolutions of `level`, its grid dense.
VolumeShape LevelShape(const HierarchyOptions& options, int num_shells, int level);

// The shape of level next_level after the fitted one (shape, x): resolutions doubled, and with
// options.sparse (and a grid a multiple of 8 cells across) only the occupied bricks that the
// training views see (OccupiedBricks).
VolumeShape NextLevelShape(const HierarchyOptions& options, const VolumeGeometry& geometry, const VolumeShape& shape,
                           std::span<const float> x, std::span<const ViewFrustum> views, int next_level);

// What the callbacks see of the level being solved.
struct HierarchyLevel {
  int level = 0, levels = 0;
  VolumeShape shape;
  int image_downscale = 1;
  int64_t rays = 0;
  MemoryEstimate memory;
  SolverOptions solver;  // as run at this level
  // The backend vector holding the current parameters while the level runs and after it is done
  // (render or score from it in a callback).
  VecId params = 0;
};

struct HierarchyCallbacks {
  // Before a level is set up; false ends the hierarchy there (e.g. a time budget spent).
  std::function<bool(int level)> before_level;
  // After SetLevel, before the first iteration.
  std::function<void(const HierarchyLevel&)> level_started;
  // After each iteration; false stops the level's solve there (and the hierarchy after it).
  std::function<bool(const HierarchyLevel&, const IterationSummary&)> iteration;
  // After each iteration the callback above goes on from: true ends the level's solve there and
  // the hierarchy goes on to the next level (e.g. a time plan); the level's status says
  // kPlanned.
  std::function<bool(const HierarchyLevel&, const IterationSummary&)> end_level;
  // After the level's solve; the backend still holds the level. `x` is its solution.
  std::function<void(const HierarchyLevel&, const SolverSummary&, const std::vector<float>& x)> level_done;
  // With stop_when_out_of_memory: the level that did not fit (h.memory says what it needed) and
  // so ended the hierarchy; SolveHierarchy returns the level before's solution (empty when the
  // hierarchy started at the level that did not fit).
  std::function<void(const HierarchyLevel&)> out_of_memory;
};

// The training photos: their full-size cameras and sizes (for the pyramid rule and occupancy),
// and their rays at an integer downscale factor of the photos (1: as they are; MakeRaySet of the
// downscaled photos).
struct TrainingViews {
  std::vector<ViewFrustum> views;
  std::function<RaySet(int factor)> rays;
};

// Where a hierarchy starts: level 0 from InitialParams (x empty), or a later level from the
// parameters carried into it (NextLevelShape and Resample of the level before).
struct HierarchyStart {
  int level = 0;
  VolumeShape shape;     // x's shape
  std::vector<float> x;  // empty: a fresh start
};

// Runs levels [start.level, levels) on `backend`. Returns the last level's solution. Throws Error
// when the solver fails, and whatever a callback throws.
std::vector<float> SolveHierarchy(Backend* backend, const VolumeGeometry& geometry, const TrainingViews& train,
                                  const HierarchyOptions& options, HierarchyStart start,
                                  const HierarchyCallbacks& callbacks);

}  // namespace perf::recon
