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
//   recon/settings.json       the options a fresh run started with (run_settings.h), for resumes
//   preview/recon_l<k>_i<j>.png  with preview_every: a held-out view during the solve
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "recon_cuda/data/training_data.h"
#include "recon_cuda/run/level_choice.h"
#include "recon_cuda/run/reconstruct_options.h"
#include "recon_cuda/solve/hierarchy.h"

namespace perf::recon {

struct LevelReport {
  int level = 0;
  VolumeShape shape;
  int image_downscale = 1;
  int64_t rays = 0;
  int iterations = 0;
  double seconds = 0;  // solver wall time of the level (excludes held-out evaluation)
  double cost = 0, train_psnr = 0, test_psnr = 0;
  std::string status;

  // recon.json's entry for the level (its checkpoint relative to `workspace`).
  nlohmann::json ToJson(const std::filesystem::path& workspace) const;
};

struct ReconstructResult {
  std::string backend;
  bool fixed_background = false;
  std::vector<LevelReport> levels;  // the levels run by this call
  double solve_seconds = 0;         // sum of the levels' solver time
  double test_psnr = 0;             // held-out PSNR of the final level (0: no held-out views)
  std::filesystem::path final_checkpoint;
  // Why final_checkpoint is not the finest level's (FinalLevelIndex); empty when it is.
  std::string final_choice;
  bool already_complete = false;    // --resume found every level done
  // Resume asked for, but the checkpoints' settings differ from this run's or are not recorded
  // (run_settings.h): why, and (restart_if_settings_changed) this run started over; empty: the
  // same, or no resume.
  std::string settings_changed;
  LevelChoice levels_choice;        // how many levels and why
  int ranks = 1;                    // processes that fitted the photos (ReconstructOptions::comm)
  int exposures = 0;                // photos whose exposure was solved (0: none)
  float gain_range[2] = {1, 1};     // the least and greatest gain of any photo and channel
  std::string memory_stop;          // automatic levels: why the hierarchy ended early (empty: it did not)
  // With a time budget: the plan, what each level ran and why the plan ended the run (TimePlanner::ToJson); null without.
  nlohmann::json time_plan;
  // The turn searched for each group the repair moved onto the object (turn_search.h TurnSearch::ToJson).
  nlohmann::json turn_search = nlohmann::json::array();

  // What recon.json records beyond the levels.
  HierarchyOptions hierarchy;               // as derived for the scene (ReconstructOptions::Hierarchy)
  std::string opacity_residual = "off";     // "alpha", "auxiliary" or "off"
  float opacity_weight = 0;
  nlohmann::json excluded_views = nlohmann::json::array();  // left out on import: name, because
  nlohmann::json photo_fits;                // after the first level (photo_fit.h); null before
  nlohmann::json box_faces = nlohmann::json::array();    // the last first-level fit's (box_check.h)
  std::string box_warning;
  nlohmann::json box_growths = nlohmann::json::array();  // BoxGrowth::ToJson of each
  // The refined cameras of the last level (refined_poses.h CorrectionsToJson); null without.
  nlohmann::json pose_corrections;
  std::string pose_warning;  // the large corrections (LargeCorrectionsWarning); empty: none

  // recon.json: the settings `options` ran with, the choices made and every level run.
  nlohmann::json ToJson(const ReconstructOptions& options) const;
};

ReconstructResult Reconstruct(const ReconstructOptions& options);

// Which of `levels` (those one call ran, coarse to fine) is final: the one that scored best on
// the held-out views, the finer of equals, so that a finer level that scores worse than the one
// before it is not what the outputs come from; the last without held-out views. -1: none.
int FinalLevelIndex(const std::vector<LevelReport>& levels, bool scored);

// The hierarchy's view of training photos (each level's rays from the photos downscaled by its
// pyramid factor); `train` must outlive it. all_views: every training view (SplitViews), when
// `train` is only this rank's share (empty: train's own); with `comm`, the rays are numbered
// among all ranks' rays.
TrainingViews ViewsForHierarchy(const std::vector<PosedImage>& train, Communicator* comm = nullptr,
                                std::vector<ViewFrustum> all_views = {});

// A few lines for the terminal.
std::string ReconstructSummary(const ReconstructResult& r);

}  // namespace perf::recon
