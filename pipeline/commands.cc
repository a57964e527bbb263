// Options shared by several `perf` subcommands (commands.h).
#include "pipeline/commands.h"

#include <CLI/CLI.hpp>
#include <csignal>
#include <iostream>
#include "common/errors.h"
#include "common/inputs.h"
#include "common/owned_files.h"
#include "export/export_set.h"
#include "common/system_memory.h"
#include "pipeline/cli_choice.h"
#include "recon_cuda/core/render_rule.h"

namespace perf {

void AddThreadsOption(CLI::App* cmd, int* threads, int all_cores) {
  const int most = MaxWorkerThreads();
  cmd->add_option("-j,--threads", *threads, StrCat("Worker threads (", all_cores, ": all cores; at most ", most, ")"))
      ->check(CLI::Validator(
          [all_cores, most](std::string& v) -> std::string {
            int n = 0;
            if (!CLI::detail::lexical_cast(v, n) || (n != all_cores && (n < 1 || n > most))) {
              return StrCat("-j ", v, ": must be ", all_cores, " (all cores) or 1 to ", most,
                            " (8 times this machine's cores)");
            }
            return {};
          },
          "THREADS"))
      ->capture_default_str();
}

std::unique_ptr<WorkspaceLock> LockWorkspace(const std::filesystem::path& workspace, std::string_view command,
                                             bool create) {
  std::error_code ec;
  // A folder that is not a workspace (no scene.json) gets nothing written into it, not even the
  // lock: the stage then names what is missing.
  if (!create && !std::filesystem::is_regular_file(workspace / "scene.json", ec)) return nullptr;
  auto lock = std::make_unique<WorkspaceLock>(workspace, command);
  // Before anything is swept, written, moved or removed: what PERF made here, and the inputs.
  UseOwnershipRecord(workspace);
  ProtectRecordedInputs(workspace);
  SweepOwnedTemporaries();
  exporter::FinishStagedExport(workspace);
  return lock;
}

void RemoveNewWorkspaceOnFailure(const WorkspaceLock* lock, const std::filesystem::path& workspace,
                                 bool any_failure, const std::function<void()>& body) {
  const auto remove = [&] {
    if (lock == nullptr || !lock->created_workspace()) return;
    std::error_code ec;
    std::filesystem::remove_all(workspace, ec);  // made by this command, under its lock: all of it is ours
  };
  try {
    body();
  } catch (const InputError&) {
    remove();
    throw;
  } catch (...) {
    if (any_failure) remove();
    throw;
  }
}

namespace {

std::atomic<bool> g_stop{false};

extern "C" void OnInterrupt(int) {
  g_stop.store(true);
  std::signal(SIGINT, SIG_DFL);
}

}  // namespace

StopOnCtrlC::StopOnCtrlC() { std::signal(SIGINT, OnInterrupt); }
StopOnCtrlC::~StopOnCtrlC() { std::signal(SIGINT, SIG_DFL); }
const std::atomic<bool>& StopRequested() { return g_stop; }

void AddDeviceOptions(CLI::App* cmd, recon::DeviceChoice* device, int* threads) {
  using recon::DeviceChoice;
  AddChoiceOption(cmd, "--device", device,
                  {{"auto", DeviceChoice::kAuto}, {"cpu", DeviceChoice::kCpu}, {"cuda", DeviceChoice::kCuda}},
                  "Backend: cpu, cuda, or auto (cuda when a device is visible)");
  AddThreadsOption(cmd, threads, 0);
}

void AddCameraRefinementOptions(CLI::App* cmd, recon::PoseChoice* poses, bool* refine_focal) {
  using recon::PoseChoice;
  AddChoiceOption(cmd, "--refine-poses", poses,
                  {{"auto", PoseChoice::kAuto}, {"on", PoseChoice::kOn}, {"off", PoseChoice::kOff}},
                  "Refine every training photo's camera (a rotation and a centre correction) with the volume in "
                  "Gauss-Newton (auto: for COLMAP photos, not for NeRF json scenes)");
  AddChoiceOption(cmd, "--refine-intrinsics", refine_focal, {{"off", false}, {"focal", true}},
                  "With refined poses: also refine each training photo's focal length (off: the imported one)");
}

void AddShDegreeOption(CLI::App* cmd, int* sh_degree, const std::string& default_text) {
  CLI::Option* option = cmd->add_option(
      "--sh-degree", *sh_degree,
      "View-dependent colour: spherical harmonics of degree 1 (3 more values per channel and cell) or 2 (8 more) "
      "beyond each cell's colour; 0: none")
      ->check(CLI::Range(0, 2));
  if (default_text.empty()) {
    option->capture_default_str();
  } else {
    option->default_str(default_text);
  }
}

namespace {
const char kShFromLevelHelp[] =
    "With --sh-degree: the first level that solves the spherical harmonics, 1 (the first) to 6, or counted from "
    "the last: 0 the last level alone, -1 the last two, down to -5 (with levels from the photos, from the last "
    "planned; a run that stops a level early for memory ends without them); the levels before fit a "
    "view-independent colour";
}  // namespace

void AddShFromLevelOption(CLI::App* cmd, int* sh_from_level) {
  cmd->add_option("--sh-from-level", *sh_from_level, kShFromLevelHelp)->capture_default_str();
}

void AddShFromLevelOption(CLI::App* cmd, std::optional<int>* sh_from_level, const std::string& default_text) {
  cmd->add_option("--sh-from-level", *sh_from_level, kShFromLevelHelp)->default_str(default_text);
}

void AddCostToleranceOption(CLI::App* cmd, double* cost_tolerance) {
  cmd->add_option("--cost-tolerance", *cost_tolerance,
                  "Gauss-Newton leaves a level early once its cost fell by less than this fraction over the last 4 "
                  "iterations (0: every level runs all its iterations)")
      ->capture_default_str();
}

void AddMinBoxOpacityOption(CLI::App* cmd, float* min_box_opacity, const std::string& use) {
  cmd->add_option("--min-box-opacity", *min_box_opacity,
                  StrCat(use, ": rays whose box opacity is below this see only the shells (the paper's floater rule: ",
                         recon::kPaperMinBoxOpacity, "; 0: off)"))
      ->check(CLI::Range(0.0f, 1.0f))
      ->capture_default_str();
}

}  // namespace perf
