// What `perf reconstruct` is asked to do (ReconstructOptions, filled by the CLI) and the
// hierarchy's options derived from it for a scene (ReconstructOptions::Hierarchy).
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/comm.h"
#include "recon_cuda/backends/make_backend.h"
#include "recon_cuda/core/render_rule.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/level_choice.h"
#include "recon_cuda/run/photo_fit.h"
#include "recon_cuda/run/time_plan.h"
#include "recon_cuda/run/turn_search.h"
#include "recon_cuda/solve/hierarchy.h"

namespace perf {
struct Scene;
}

namespace perf::recon {

// The shells (--background): learn them (the paper), or keep them fixed at scene.json's
// background, the colour RGBA photos were composited over on import; kAuto is fixed when every
// photo had an alpha channel (e.g. NeRF synthetic), learned otherwise.
enum class BackgroundChoice { kAuto, kFixed, kLearn };

// Per-photo exposure (--exposure): solve each training photo's gain and offset per channel with
// the volume, or not; kAuto solves them for photos from COLMAP (real captures) and not for NeRF
// json scenes (synthetic renders share one exposure).
enum class ExposureChoice { kAuto, kOn, kOff };

// Camera refinement (--refine-poses): solve a rotation and a centre correction for every training
// photo with the volume (pose.h), from level refine_poses_from on, or not. kAuto: see RefinesPoses.
enum class PoseChoice { kAuto, kOn, kOff };

// The grid's smoothness weight chosen where the background is learned (--smooth-grid's default
// there; 0 where it is fixed).
inline constexpr double kAutoSmoothGrid = 0.3;
// The pose prior's default (--pose-prior, SolverOptions::pose_prior). 0.03 recovers perturbed lego
// cameras better than 0.1 and keeps exact ones; with per-photo focal lengths 0.1, which holds the
// distance that a focal length trades against (docs/tuning.md "Camera refinement").
inline constexpr double kDefaultPosePrior = 0.03;
inline constexpr double kFocalPosePrior = 0.1;

// --cost-tolerance's default (SolverOptions::cost_tolerance): a level ends once its cost fell by
// less than 2 % in 4 iterations (docs/tuning.md "A level ends when its cost flattens").
inline constexpr double kDefaultCostTolerance = 0.02;

struct ReconstructOptions {
  std::filesystem::path workspace;
  // The ranks of the job (comm.h; nullptr: one process). Each rank loads and fits its share of
  // the photos; rank 0 alone writes the workspace and reports progress.
  Communicator* comm = nullptr;
  // With several ranks on the CUDA backend: makes the communicator that sums device memory where
  // it lies (NCCL, nccl_comm.h) over `comm`; empty: the sums go through host copies.
  std::function<std::unique_ptr<Communicator>(Communicator& host)> device_comm;
  DeviceChoice device = DeviceChoice::kAuto;
  int threads = 0;              // CPU worker threads, 0: all cores
  int levels = 0;               // 0: chosen from the photos (level_choice.h)
  int max_resolution = 0;       // automatic levels: the finest grid at most this (0: DefaultMaxResolution)
  int start_resolution = 32;
  int iterations = 30;          // solver iterations per level (paper: 30)
  std::vector<int> level_iterations;  // per level, overriding `iterations` for the levels given
  // The solver of every level (max_iterations and seed are set per level). Its smoothness
  // weights: smooth_shells 0.1; smooth_grid < 0 (the default) is chosen for the scene,
  // kAutoSmoothGrid where the background is learned and 0 where it is fixed. Adam runs none.
  // Gauss-Newton leaves a level early once its cost flattens (kDefaultCostTolerance). Its
  // pose_prior is replaced by pose_prior below.
  SolverOptions solver = DefaultSolver();
  InitOptions init;
  bool init_shells_from_photos = false;  // shells start at the training photos' mean colour
  BackgroundChoice background = BackgroundChoice::kAuto;
  // Per-photo exposure; solver.exposure_prior weighs its prior.
  ExposureChoice exposure = ExposureChoice::kAuto;
  // Camera refinement. Levels before refine_poses_from (1: the first, as the log numbers them) fit
  // the volume on the imported poses, the others refine them. pose_prior weighs the prior toward
  // the imported poses (solver.pose_prior); unset: kDefaultPosePrior, or kFocalPosePrior with
  // refine_focal.
  PoseChoice poses = PoseChoice::kAuto;
  std::optional<double> pose_prior;
  int refine_poses_from = 1;
  // With refined poses, also each training photo's focal length (--refine-intrinsics focal): a
  // scale of fx and fy (PoseParam's value 3), its own per photo; false: the imported intrinsics.
  bool refine_focal = false;
  // View-dependent colour: spherical harmonics of this degree (0, 1 or 2) beyond each cell's
  // colour (ray_types.h ShParam); 0: none. Solved from level sh_from_level on (1: the first;
  // counted from the last: 0, the default, the last level alone, -1 the last two; ShFromLevelIndex).
  int sh_degree = 0;
  int sh_from_level = 0;
  ResidualSettings residuals;
  // Coarse levels fit downscaled photos: the largest power-of-two downscale that keeps a voxel
  // at least one pixel wide in the median view (fewer rays, same information at that level).
  bool pyramid = true;
  bool dense = false;  // every level's grid dense (else levels after the first keep the occupied bricks)
  // Where the first level's density reaches a side or top face of the box, grow the box there and
  // fit that level again (box_check.h; at most kMaxBoxGrowths times); false: only warn.
  bool grow_box = true;
  // After the first level, the training photos that fit far worse than the median are named
  // (photo_fit.h; output, log and recon.json) and kept.
  PhotoFitOptions photo_fit;
  // Before a fresh hierarchy, the turn of each group the ghost repair moved onto the object
  // (scene.json turn_group) is searched against a first level of the other photos (turn_search.h).
  TurnSearchOptions turn_search;
  OccupancyOptions occupancy;  // which bricks a sparse level keeps
  bool resume = false;          // continue after the last checkpoint instead of starting over
  // With resume: start over instead when the last run's recorded settings (run_settings.h) differ
  // from these (perf run, whose outputs must be what its command line asks for); false: resume
  // anyway and name the differences (perf reconstruct --resume, which may add a level).
  bool restart_if_settings_changed = false;
  int preview_every = 0;        // write a held-out preview every K iterations (0: never)
  std::string preview_image;    // the photo the previews show (scene.json name); empty: the first held-out one
  int eval_every = 0;           // held-out PSNR every K iterations (0: at the end of each level)
  float min_box_opacity = kDefaultMinBoxOpacity; // the render rule (render_rule.h), for previews and held-out PSNR

  // Progress: called after each iteration and at level boundaries.
  struct Event {
    int level = 0, levels = 0, iteration = 0, iterations = 0;
    double cost = 0, train_psnr = 0;
    std::string message;  // non-empty: a line to print
  };
  std::function<void(const Event&)> on_event;
  // The solver's volume for a live page (perf run --view, viewer/live_view.h): rank 0 hands over
  // the level's parameters after an iteration, the level's first and then at most every
  // volume_every_seconds (5; the copy's seconds are logged per level as volume_seconds). Unset:
  // never.
  std::function<void(Checkpoint volume, int iteration)> on_volume;
  double volume_every_seconds = 5;
  // A time budget for the run this reconstruction is part of (perf run --time-budget,
  // time_plan.h): levels and iterations are planned to end by its deadline less what follows the
  // solve. Unset: none. Applied in a single process only (under mpirun it is said and ignored).
  std::optional<TimeBudget> time_budget;

  // Throws InputError naming the bad option.
  void Check() const;

  // The hierarchy these options ask for on `scene` with `levels` levels: the background fixed or
  // learned, the smoothness weights, the photos whose exposures are solved; stops early for
  // memory only where the levels were chosen automatically.
  HierarchyOptions Hierarchy(const Scene& scene, const LevelChoice& levels) const;

  // The pose prior's weight the solver gets: pose_prior, or its default for refine_focal.
  double PosePrior() const;

  static SolverOptions DefaultSolver();
};

// Whether `background` fixes the shells for this scene.
bool FixedBackground(BackgroundChoice background, const Scene& scene);

// Throws InputError (naming --refine-intrinsics) when the focal length is asked for with the poses
// off: it is refined with them.
void CheckCameraRefinement(PoseChoice poses, bool refine_focal);

// Throws InputError (naming --sh-degree) unless the degree is 0, 1 or 2.
void CheckShDegree(int sh_degree);
void CheckShFromLevel(int sh_from_level);  // -5 to 6
// The 0-based level the bands join: sh_from_level 1..6 counts from the first (past the last: an
// InputError with set levels, the last with levels from the photos), 0..-5 back from the last.
int ShFromLevelIndex(int sh_from_level, const LevelChoice& choice);

// Whether `exposure` solves the photos' exposures for this scene (kAuto: COLMAP photos).
bool SolvesExposures(ExposureChoice exposure, const Scene& scene);

// Whether `poses` refines the training photos' poses for this scene with this solver (kAuto: for
// photos from COLMAP, real captures whose registration refinement improves, not for NeRF json
// scenes, whose poses are exact (docs/tuning.md "Camera refinement"); Adam never refines them).
bool RefinesPoses(PoseChoice poses, const Scene& scene, SolverType solver);

// The hierarchy's background as perf reconstruct sets it: fixed or not (FixedBackground), and
// the colour fixed shells hold (scene.json's background).
void SetHierarchyBackground(BackgroundChoice background, const Scene& scene, HierarchyOptions* options);

}  // namespace perf::recon
