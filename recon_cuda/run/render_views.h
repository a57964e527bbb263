// `perf render`: draws training or held-out cameras of a workspace from a checkpoint (the final
// one by default) with the render path (no jitter; the paper's box-opacity rule on request, render_rule.h), writes
// PNGs, and scores each against its photo.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "recon_cuda/backends/make_backend.h"
#include "recon_cuda/core/render_rule.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/evaluation.h"

namespace perf::recon {

// A checkpoint in a backend, ready to render: its parameters are vector 0.
struct LoadedCheckpoint {
  std::filesystem::path path;
  Checkpoint checkpoint;
  std::unique_ptr<Backend> backend;
  static constexpr VecId kParams = 0;
};

// The checkpoint a workspace's outputs come from: the one recon/recon.json names as final where
// the run that wrote it also wrote the newest checkpoint (recon.json no older than it; a finer
// level that scored worse held-out is not final: FinalLevelIndex), else the highest level; empty
// when there is none.
std::filesystem::path FinalCheckpointPath(const std::filesystem::path& workspace);

// `checkpoint`, or FinalCheckpointPath when empty; IoError saying to run perf
// reconstruct when there is none, and the reader's errors for a missing or damaged file.
LoadedCheckpoint LoadForRendering(const std::filesystem::path& workspace, const std::filesystem::path& checkpoint,
                                  DeviceChoice device, int threads);

// The photos' exposures the checkpoint holds, placed at the scene's training cameras (exposure.h;
// none when it solved none). InputError when the scene's training photos are not the ones fitted.
PhotoCorrections CorrectionsOf(const LoadedCheckpoint& loaded, const Scene& scene);

// The scene posed as the checkpoint's refined cameras place every view (refined_poses.h
// PosedAsRefined of WithRefinedPoses); the scene itself when the checkpoint refined none.
Scene PosedAsCheckpoint(const LoadedCheckpoint& loaded, const Scene& scene);

// Which of a workspace's photos a command renders or scores (--split).
enum class ViewSplit { kTest, kTrain, kAll };

struct RenderViewsOptions {
  std::filesystem::path workspace;
  std::filesystem::path checkpoint;  // empty: the highest level in recon/
  std::filesystem::path out_dir;     // empty: WORKSPACE/renders
  ViewSplit split = ViewSplit::kTest;
  std::vector<std::string> names;    // only these images (scene.json names); empty: the split
  float min_box_opacity = kDefaultMinBoxOpacity;  // render_rule.h
  bool write_opacity = false;        // also <name>_opacity.png (1 - T_box)
  DeviceChoice device = DeviceChoice::kAuto;
  int threads = 0;
  std::function<void(int done, int total)> progress;
};

struct RenderViewsResult {
  std::filesystem::path checkpoint;
  std::vector<ViewScore> scores;
  std::vector<std::filesystem::path> files;
  double mean_psnr = 0;
};

RenderViewsResult RenderViews(const RenderViewsOptions& options);

}  // namespace perf::recon
