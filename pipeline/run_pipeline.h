// `perf run`: photos (or a COLMAP model, or a NeRF transforms.json) to masks, volume, mesh and
// report in one command. The stages of DESIGN.md "Stages and the workspace" run in order, each
// skipped when its outputs are present and newer than its inputs (unless `force`):
//   sfm          only from --images alone: WORKSPACE/sparse/0 present -> skipped;
//   import       scene.json newer than the model (or transforms.json);
//   reconstruct  resumed after the last checkpoint newer than scene.json, so a killed run picks
//                up at the last finished level; started over when scene.json is newer;
//   export       export.json newer than the final checkpoint;
//   eval         report.json newer than the final checkpoint.
// Ctrl-C stops between solver iterations (or between images) and leaves every file whole.
#pragma once

#include <atomic>
#include <nlohmann/json.hpp>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "common/comm.h"
#include "recon_cuda/backends/make_backend.h"
#include "recon_cuda/run/reconstruct_options.h"

namespace perf {

struct PresetSettings;
namespace viewer {
class LiveView;
}

struct RunOptions {
  std::filesystem::path images, colmap, nerf, workspace;
  std::string preset = "default";  // preview, default, high
  recon::DeviceChoice device = recon::DeviceChoice::kAuto;
  int threads = 0;
  bool force = false;
  bool keep_bad_poses = false;  // import: train and score on photos whose pose looks wrong too
  // import: a --colmap model that holds a ghost group is made again from the photos and the new
  // one imported where it is better (sfm_import/ghost_repair.h); false (--no-repair): as given.
  bool repair = true;
  recon::ExposureChoice exposure = recon::ExposureChoice::kAuto;  // reconstruct: per-photo exposure
  recon::PoseChoice poses = recon::PoseChoice::kAuto;             // reconstruct: camera refinement
  bool refine_focal = false;                                       // reconstruct: and the focal lengths
  double cost_tolerance = recon::kDefaultCostTolerance;  // reconstruct: a level ends once its cost flattens
  // Overrides of the preset (0: the preset's).
  int max_size = 0, levels = 0, iterations = 0, max_resolution = 0;
  // --time-budget: the whole run's seconds (levels and iterations are planned to fit them,
  // recon_cuda/run/time_plan.h); unset: the preset's for the device (DefaultTimeBudget); 0: none.
  std::optional<double> time_budget;
  int sh_degree = -1;  // reconstruct: view-dependent colour (-1: the preset's)
  std::optional<int> sh_from_level;  // reconstruct: the level its bands join (unset: the preset's)
  bool quiet = false;
  std::filesystem::path log_json;  // JSON lines of stage events for scripts (empty: none)
  const std::atomic<bool>* stop = nullptr;  // set (by a signal handler) to stop at a safe point
  // --view: the live page, told each stage and iteration; the solve also renders a preview each
  // iteration for it. nullptr: no page.
  viewer::LiveView* live = nullptr;
  std::string view_image;  // --view-image: the photo the live page's renders show (empty: the first held-out one)
  // Under mpirun (comm.h): rank 0 runs every stage; the other ranks wait for its import and join
  // only the reconstruction, each fitting its share of the photos. nullptr: one process.
  Communicator* comm = nullptr;

  void Check() const;  // InputError naming the option

  // The reconstruction stage's options under `preset` (the same on every rank): it resumes when
  // the last checkpoint is newer than scene.json and `force` is not set; else it starts over, and
  // the earlier run's checkpoints stay until it has a level of its own (previous_run.h).
  recon::ReconstructOptions ReconstructStage(const PresetSettings& preset) const;
};

// What a preset sets (printed at the start of a run).
struct PresetSettings {
  int max_size = 0;     // import: longest image side (0: full size)
  int levels = 0;       // reconstruct: hierarchy levels (0: from the photos, level_choice.h)
  int max_resolution = 0;  // with levels 0: the finest grid at most (0: the backend's default)
  int iterations = 30;  // per level
  int sh_degree = 0;    // reconstruct: view-dependent colour (0: none)
  int sh_from_level = 0;  // the level its bands join (recon::ShFromLevelIndex; 0: the last alone)
  int orbit_frames = 60;
  std::string Describe() const;
};
PresetSettings PresetFor(const RunOptions& options);

struct StageReport {
  std::string name;
  bool skipped = false;
  std::string reason;  // why it ran or was skipped
  double seconds = 0;
};

// --time-budget's default: preview 10 min on a CPU and 2 on a GPU, default 60 and 15, high 240
// and 60 (each well above what the preset takes on the examples and bonsai, so that it binds
// only on captures that would run for longer).
double DefaultTimeBudget(const std::string& preset, bool gpu);

// A duration as a user writes it: "90" or "90s", "10m", "1.5h", "1h30m", "none" (0). Throws
// InputError naming `option` and the value otherwise.
double ParseDuration(const std::string& text, const std::string& option);

struct RunResult {
  std::vector<StageReport> stages;
  double test_psnr = 0, test_ssim = 0, mask_coverage = 0;
  double mask_iou = -1;  // against the true masks when there are any
  std::filesystem::path final_checkpoint;
  double seconds = 0;
  double time_budget = 0;         // the budget kept (0: none)
  std::string time_budget_from;   // "--time-budget" or the preset's default for the device
  nlohmann::json time_plan;       // the reconstruction's plan (ReconstructResult::time_plan)
  nlohmann::json repair;          // the model's check and repair (RepairResult::ToJson); null: none
};

RunResult RunPipeline(const RunOptions& options);

// The end-of-run summary: where each output is, the held-out scores, time per stage.
std::string RunSummary(const RunOptions& options, const RunResult& result);

}  // namespace perf
