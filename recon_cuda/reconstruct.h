// `perf reconstruct`: the hierarchy of DESIGN.md "Hierarchy" over a workspace made by
// `perf import`. Level 0 starts from random colours and low opacity at start_resolution^3 (and
// start_resolution^2 texels per face); each level runs the solver for a fixed number of
// iterations, is checkpointed, and fills the next level (every resolution doubled) by
// interpolation.
//
// Workspace outputs:
//   recon/level_<k>.perfvol   checkpoint after level k (checkpoint.h)
//   recon/log.jsonl           one JSON line per solver iteration (and one per level / resume)
//   recon/recon.json          summary: levels done, final checkpoint, settings, held-out PSNR
//   preview/recon_l<k>_i<j>.png  with preview_every: a held-out view during the solve
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "recon_cuda/device_choice.h"
#include "recon_cuda/hierarchy.h"
#include "recon_cuda/level_choice.h"
#include "recon_cuda/photo_fit.h"
#include "recon_cuda/render_rule.h"
#include "recon_cuda/solver.h"
#include "recon_cuda/training_data.h"

namespace perf {
struct Scene;
}

namespace perf::recon {

// --smooth-grid's automatic value where the background is learned (the bonsai example: +0.1 dB
// held-out, +1.1 dB inside the mask).
inline constexpr double kAutoSmoothGrid = 0.3;

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
  SolverOptions solver;         // max_iterations and seed are set per level; smooth_* from below
  // Smoothness residuals (SolverOptions::smooth_grid, smooth_shells; docs/tuning.md 2026-12-02).
  // The grid's: < 0 picks kAutoSmoothGrid where the background is learned (real photos) and 0
  // where it is fixed (photos with alpha: lego loses 1.8 dB with 0.1).
  double smooth_grid = -1;
  double smooth_shells = 0.1;
  InitOptions init;
  bool init_shells_from_photos = false;  // shells start at the training photos' mean colour
  // The shells (device_choice.h); a known background is information (+0.7 dB on lego, docs/tuning.md).
  BackgroundChoice background = BackgroundChoice::kAuto;
  // Per-photo exposure (device_choice.h ExposureChoice; solver.exposure_prior weighs its prior).
  ExposureChoice exposure = ExposureChoice::kAuto;
  // View-dependent colour: spherical harmonics of this degree (0, 1 or 2) beyond each cell's
  // colour (ray_types.h ShParam); 0: none (docs/tuning.md "View dependence").
  int sh_degree = 0;
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
  OccupancyOptions occupancy;  // which bricks a sparse level keeps
  bool resume = false;          // continue after the last checkpoint instead of starting over
  int preview_every = 0;        // write a held-out preview every K iterations (0: never)
  int eval_every = 0;           // held-out PSNR every K iterations (0: at the end of each level)
  float min_box_opacity = kDefaultMinBoxOpacity; // the render rule (render_rule.h), for previews and held-out PSNR

  // Progress: called after each iteration and at level boundaries.
  struct Event {
    int level = 0, levels = 0, iteration = 0, iterations = 0;
    double cost = 0, train_psnr = 0;
    std::string message;  // non-empty: a line to print
  };
  std::function<void(const Event&)> on_event;

  // Throws InputError naming the bad option.
  void Check() const;
};

struct LevelReport {
  int level = 0;
  VolumeShape shape;
  int image_downscale = 1;
  int64_t rays = 0;
  int iterations = 0;
  double seconds = 0;  // solver wall time of the level (excludes held-out evaluation)
  double cost = 0, train_psnr = 0, test_psnr = 0;
  std::string status;
};

// Whether `background` fixes the shells for this scene.
bool FixedBackground(BackgroundChoice background, const Scene& scene);

// Whether `exposure` solves the photos' exposures for this scene (kAuto: COLMAP photos).
bool SolvesExposures(ExposureChoice exposure, const Scene& scene);

// The hierarchy's background as perf reconstruct sets it: fixed or not (FixedBackground), and
// the colour fixed shells hold (scene.json's background).
void SetHierarchyBackground(BackgroundChoice background, const Scene& scene, HierarchyOptions* options);

struct ReconstructResult {
  std::string backend;
  bool fixed_background = false;
  std::vector<LevelReport> levels;  // the levels run by this call
  double solve_seconds = 0;         // sum of the levels' solver time
  double test_psnr = 0;             // held-out PSNR of the final level (0: no held-out views)
  std::filesystem::path final_checkpoint;
  bool already_complete = false;    // --resume found every level done
  LevelChoice levels_choice;        // how many levels and why
  int ranks = 1;                    // processes that fitted the photos (ReconstructOptions::comm)
  int exposures = 0;                // photos whose exposure was solved (0: none)
  float gain_range[2] = {1, 1};     // the least and greatest gain of any photo and channel
  std::string memory_stop;          // automatic levels: why the hierarchy ended early (empty: it did not)
};

ReconstructResult Reconstruct(const ReconstructOptions& options);

// The hierarchy's view of training photos (each level's rays from the photos downscaled by its
// pyramid factor); `train` must outlive it. all_views: every training view (SplitViews), when
// `train` is only this rank's share (empty: train's own); with `comm`, the rays are numbered
// among all ranks' rays.
TrainingViews ViewsForHierarchy(const std::vector<PosedImage>& train, Communicator* comm = nullptr,
                                std::vector<ViewFrustum> all_views = {});

// A few lines for the terminal.
std::string ReconstructSummary(const ReconstructResult& r);

}  // namespace perf::recon
