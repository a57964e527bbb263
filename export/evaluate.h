// `perf eval WORKSPACE`: scores the reconstruction on the held-out views and writes
// WORKSPACE/report.json and the self-contained WORKSPACE/report.html.
//   - PSNR and SSIM per held-out view and their means, over the whole image and inside our own
//     binary foreground mask (the paper's metric for real scenes);
//   - when a true foreground exists (the alpha of NeRF-synthetic photos, kept by perf import in
//     WORKSPACE/alpha/, or mask images given with --gt-masks DIR, named like the photos), the
//     IoU, precision and recall of our binary masks against it, per image and pooled.
#pragma once

#include <algorithm>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "export/metrics.h"
#include "recon_cuda/backends/make_backend.h"
#include "recon_cuda/core/render_rule.h"

namespace perf::exporter {

// The eval's test-time pose fit: 12 Gauss-Newton iterations on the held-out photos at most 100 px
// across. The same scores as at their full size, 11x sooner (bonsai's 64^3 level, 10 views of
// 400 px: 21.72 against 21.71 dB, 13.9 against 156.6 s; docs/tuning.md "The eval's pose fit").
inline constexpr int kPoseFitIterations = 12;
inline constexpr int kPoseFitSide = 100;

// The least integer downscale that brings a width x height photo's longer side to at most `side`
// pixels (side 0: 1, as it is).
inline int PoseFitDownscale(int width, int height, int side) {
  return side > 0 ? std::max(1, (std::max(width, height) + side - 1) / side) : 1;
}

struct EvalOptions {
  std::filesystem::path workspace;
  std::filesystem::path checkpoint;  // empty: the final one (recon::FinalCheckpointPath)
  std::filesystem::path gt_masks;    // optional folder of true masks, in the photos' frame
  double mask_threshold = 0.7;
  float min_box_opacity = recon::kDefaultMinBoxOpacity;  // renders: the render rule (render_rule.h)
  bool html = true;
  // The test-time pose fit of the held-out views (EvalResult::pose_fit, where the volume refines
  // poses): its Gauss-Newton iterations, and the photos downscaled (area) by the least integer
  // factor that brings their longer side to at most pose_fit_side pixels (0: as they are).
  // docs/tuning.md "The eval's pose fit".
  int pose_fit_iterations = kPoseFitIterations;
  int pose_fit_side = kPoseFitSide;
  recon::DeviceChoice device = recon::DeviceChoice::kAuto;
  int threads = 0;
  std::function<void(const std::string& step, int done, int total)> progress;
};

struct ViewReport {
  std::string name;
  ImageScores scores;          // the headline: the camera from its neighbours' corrections
  double psnr_pose_fit = -1;   // after the test-time fit of its camera alone (-1: not run)
  double pose_fit_degrees = 0, pose_fit_centre_fraction = 0;  // how far that fit moved the camera
  std::string pose_doubt;  // scene.json's: why its imported pose is in doubt (empty: none)
};

struct MaskReport {
  std::string name;
  std::string split;
  MaskAgreement agreement;
};

struct EvalResult {
  std::filesystem::path checkpoint;
  std::vector<ViewReport> views;
  double pose_fit_seconds = 0;      // the test-time pose fit's (with pose_fit)
  ImageScores mean;                 // means over views (masked ones over views with a mask)
  std::string mask_truth;           // "alpha", "gt-masks" or "" (none)
  std::vector<MaskReport> masks;
  MaskAgreement pooled;             // over every pixel of every image with a true mask
  double mean_iou = 0;              // mean of the per-image IoUs
  // With refined cameras (--refine-poses), the held-out views are scored a second way: after a
  // test-time fit of each view's camera alone against the frozen volume (recon/pose_fit.h), the
  // protocol of pose-refining NeRF papers. Reported beside the headline, never instead of it.
  bool pose_fit = false;
  double mean_psnr_pose_fit = 0;
};

EvalResult RunEval(const EvalOptions& options);

}  // namespace perf::exporter
