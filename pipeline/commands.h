// The `perf` subcommands. Each Add*Command registers its options and a callback on `app`;
// errors propagate as perf::Error and are turned into messages and exit codes by main().
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "common/workspace_lock.h"
#include "recon_cuda/backends/make_backend.h"
#include "recon_cuda/run/reconstruct_options.h"

namespace CLI {
class App;
}
namespace perf::viewer {
class LiveView;
struct ViewOptions;
}

namespace perf {

void AddImportCommand(CLI::App& app);
void AddSfmCommand(CLI::App& app);
void AddReconstructCommand(CLI::App& app);
void AddRenderCommand(CLI::App& app);
void AddExportCommand(CLI::App& app);
void AddEvalCommand(CLI::App& app);
void AddRunCommand(CLI::App& app);
void AddViewCommand(CLI::App& app);

// -j,--threads: `all_cores` (0, or -1 for colmap) or 1 to 8x the cores; anything else is exit 2.
void AddThreadsOption(CLI::App* cmd, int* threads, int all_cores);

// Takes the workspace's writer lock (common/workspace_lock.h) for the command's life, installs the
// workspace's record of what PERF wrote (common/owned_files.h) and the recorded inputs, removes the
// temporaries killed runs left and finishes or drops an export a kill interrupted
// (export/export_set.h). Throws InputError when another perf command holds the lock. Commands that
// need an existing workspace pass create = false: a folder without scene.json gets no lock (nullptr,
// nothing written into it) and the stage's own message ("no scene.json here").
std::unique_ptr<WorkspaceLock> LockWorkspace(const std::filesystem::path& workspace, std::string_view command,
                                             bool create = false);

// Runs `body` with `lock` held (may be null: another rank's). When it throws and the lock made the
// workspace folder, the folder goes with it: after any failure (`any_failure`), or only when the
// command refused its input (InputError: nothing of use was made; a failed COLMAP step keeps its log).
void RemoveNewWorkspaceOnFailure(const WorkspaceLock* lock, const std::filesystem::path& workspace,
                                 bool any_failure, const std::function<void()>& body);

// Ctrl-C while one lives: the first sets StopRequested() (the command stops at its next safe
// point and says how to resume, exit 130); the second kills as usual.
class StopOnCtrlC {
 public:
  StopOnCtrlC();
  ~StopOnCtrlC();
  StopOnCtrlC(const StopOnCtrlC&) = delete;
  StopOnCtrlC& operator=(const StopOnCtrlC&) = delete;
};
const std::atomic<bool>& StopRequested();

// --device and -j,--threads: the same for every command that runs a backend.
void AddDeviceOptions(CLI::App* cmd, recon::DeviceChoice* device, int* threads);

// --refine-poses and --refine-intrinsics: camera refinement, the same for perf run and perf
// reconstruct.
void AddCameraRefinementOptions(CLI::App* cmd, recon::PoseChoice* poses, bool* refine_focal);

// --sh-degree: view-dependent colour, the same for perf run and perf reconstruct; `default_text`
// replaces the shown default (empty: *sh_degree's value).
void AddShDegreeOption(CLI::App* cmd, int* sh_degree, const std::string& default_text = "");
// --sh-from-level: the level the bands join (recon::ShFromLevelIndex); perf reconstruct's with its
// default, perf run's unset unless given (the preset's, shown as `default_text`).
void AddShFromLevelOption(CLI::App* cmd, int* sh_from_level);
void AddShFromLevelOption(CLI::App* cmd, std::optional<int>* sh_from_level, const std::string& default_text);

// --cost-tolerance: when a level's Gauss-Newton ends early, the same for perf run and perf reconstruct.
void AddCostToleranceOption(CLI::App* cmd, double* cost_tolerance);

// --view, --view-port, --view-image: perf view's page while the command runs (viewer/live_view.h);
// `after` says what becomes of the page when the command ends.
void AddLiveViewOptions(CLI::App* cmd, bool* view, int* port, std::string* image, const std::string& after);

// The page for `command` over `workspace` when `view` (rank 0 only; nullptr otherwise): bound,
// serving, at stage `command`, and its URL and ssh -L line printed.
std::unique_ptr<viewer::LiveView> StartLiveView(bool view, bool root, viewer::ViewOptions options,
                                                const std::filesystem::path& workspace, const std::string& command);

// --min-box-opacity: the render rule (recon_cuda/core/render_rule.h) for what `use` names.
void AddMinBoxOpacityOption(CLI::App* cmd, float* min_box_opacity, const std::string& use);

}  // namespace perf
