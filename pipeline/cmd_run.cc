// `perf run`: every stage in one command (run_pipeline.h), with Ctrl-C stopping at a safe point.
#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <chrono>
#include <iostream>
#include <thread>

#include "common/comm.h"
#include "common/errors.h"
#include "pipeline/cli_choice.h"
#include "pipeline/commands.h"
#include "pipeline/run_pipeline.h"
#include "viewer/live_view.h"

namespace perf {

void AddRunCommand(CLI::App& app) {
  struct Args {
    RunOptions o;
    std::string images, colmap, nerf, workspace, log_json, log_level = "info", time_budget;
    bool view = false;
    bool no_repair = false;
    viewer::ViewOptions view_options;
  };
  auto args = std::make_shared<Args>();
  RunOptions& o = args->o;
  CLI::App* cmd = app.add_subcommand(
      "run",
      "Photos (or a COLMAP model, or a NeRF transforms.json) to masks, volume, mesh and report: runs sfm, import, "
      "reconstruct, export and eval, skipping stages whose outputs are up to date and made with the same settings. "
      "Ctrl-C stops cleanly; run the same "
      "command again to resume.");
  cmd->add_option("--images", args->images, "Folder of photos (alone: runs COLMAP first; with --colmap: its photos)");
  cmd->add_option("--colmap", args->colmap, "Existing COLMAP sparse model folder (e.g. project/sparse/0)");
  cmd->add_option("--nerf", args->nerf, "NeRF-synthetic transforms.json");
  cmd->add_option("-w,--workspace", args->workspace, "Workspace folder")->required();
  cmd->add_option("--preset", o.preset, "preview, default or high (quality vs time)")->capture_default_str();
  cmd->add_option("--max-size", o.max_size, "Override the preset: longest image side in pixels");
  cmd->add_option("--levels", o.levels, "Override the preset: hierarchy levels");
  cmd->add_option("--max-resolution", o.max_resolution,
                  "Override the preset: levels from the photos, the finest grid at most this many cells across");
  cmd->add_option("--iterations", o.iterations,
                  "Override the preset: Gauss-Newton iterations per level (at most: see --cost-tolerance)");
  cmd->add_option("--time-budget", args->time_budget,
                  "The whole run's time, e.g. 90s, 10m, 1h30m: the reconstruction plans its levels and iterations to "
                  "end within it, export and eval included (default: the preset's for the device, 10m/60m/4h on a CPU "
                  "and 2m/15m/1h on a GPU for preview/default/high; none: no budget)");
  AddDeviceOptions(cmd, &o.device, &o.threads);
  cmd->add_flag("--force", o.force, "Re-run every stage even when its outputs are up to date");
  using recon::ExposureChoice;
  AddChoiceOption(cmd, "--exposure", &o.exposure,
                  {{"auto", ExposureChoice::kAuto}, {"on", ExposureChoice::kOn}, {"off", ExposureChoice::kOff}},
                  "Solve each photo's exposure (gain and offset per channel; auto: for COLMAP photos)");
  AddCameraRefinementOptions(cmd, &o.poses, &o.refine_focal);
  AddShDegreeOption(cmd, &o.sh_degree, "the preset's: 1");
  AddShFromLevelOption(cmd, &o.sh_from_level, "the preset's: 2 for default (the last level when there are fewer), 0 for preview and high");
  AddCostToleranceOption(cmd, &o.cost_tolerance);
  cmd->add_flag("--no-repair", args->no_repair,
                "Import a --colmap model that holds a ghost group as given (default: make the model again from the "
                "photos with perf sfm into WORKSPACE/repair/ and import that one where it is better)");
  cmd->add_flag("--keep-bad-poses", o.keep_bad_poses,
                "Train and score on COLMAP photos whose pose looks wrong too (by default they are left out and named)");
  AddLiveViewOptions(cmd, &args->view, &args->view_options.port, &args->o.view_image,
                     "it stays up after the run until Ctrl-C");
  cmd->add_option("--log-level", args->log_level, "info (progress and summary) or quiet (errors only)")
      ->capture_default_str();
  cmd->add_option("--log-json", args->log_json, "Append JSON lines of stage events to this file (for scripts): a new file, or one PERF started");
  cmd->callback([args]() {
    RunOptions& o = args->o;
    o.images = args->images;
    o.colmap = args->colmap;
    o.nerf = args->nerf;
    o.workspace = args->workspace;
    o.log_json = args->log_json;
    o.repair = !args->no_repair;
    if (!args->time_budget.empty()) o.time_budget = ParseDuration(args->time_budget, "--time-budget");
    if (args->log_level != "info" && args->log_level != "quiet") {
      throw InputError("command line", "--log-level", args->log_level, "unknown level", "use info or quiet");
    }
    o.quiet = args->log_level == "quiet";
    o.stop = &StopRequested();
    // Under mpirun rank 0 runs the stages and holds the lock; the others join the reconstruction.
    o.comm = &World();
    const bool root = o.comm->IsRoot();
    if (!root) o.quiet = true;
    o.Check();  // before the lock, which makes the folder: a bad command line leaves no workspace
    std::unique_ptr<WorkspaceLock> lock;
    if (root) lock = LockWorkspace(o.workspace, "run", true);
    const StopOnCtrlC ctrl_c;
    const std::unique_ptr<viewer::LiveView> live = StartLiveView(args->view, root, args->view_options, o.workspace, "run");
    o.live = live.get();
    RunResult r;
    try {
      RemoveNewWorkspaceOnFailure(lock.get(), o.workspace, false, [&] { r = RunPipeline(o); });
    } catch (const Interrupted&) {
      if (live) {  // the page polls every 2 s: it says the run stopped before the server goes
        live->End("stopped");
        std::this_thread::sleep_for(std::chrono::milliseconds(2500));
      }
      throw;
    }
    if (!o.quiet) std::cout << RunSummary(o, r);  // rank 0's (the others are quiet)
    if (live) {
      live->End("finished");
      lock.reset();  // the page only reads: other commands may write the workspace now
      std::cout << "perf run: done; the page stays at " << live->Url() << " (read-only) until Ctrl-C\n" << std::flush;
      while (!StopRequested().load()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  });
}

}  // namespace perf
