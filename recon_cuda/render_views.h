// `perf render`: draws training or held-out cameras of a workspace from a checkpoint (the final
// one by default) with the render path (no jitter, the paper's 0.7 box-opacity rule), writes
// PNGs, and scores each against its photo.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "recon_cuda/evaluation.h"

namespace perf::recon {

struct RenderViewsOptions {
  std::filesystem::path workspace;
  std::filesystem::path checkpoint;  // empty: the highest level in recon/
  std::filesystem::path out_dir;     // empty: WORKSPACE/renders
  std::string split = "test";        // test, train or all
  std::vector<std::string> names;    // only these images (scene.json names); empty: the split
  float min_box_opacity = 0.7f;
  bool write_opacity = false;        // also <name>_opacity.png (1 - T_box)
  std::string device = "auto";
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
