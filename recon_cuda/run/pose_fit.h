// The cameras of given photos fitted against a frozen volume (issue 31, "held-out views scored
// two ways"): the test-time pose fit of pose-refining NeRF papers, which scores a held-out view
// after its camera alone has been fitted to its photo. Only the views' 6 pose values move
// (LevelProblem::fixed_volume); the volume, shells and every photo's colour transform stay as
// given. Never feeds back into training.
#pragma once

#include <array>
#include <vector>

#include "recon_cuda/data/training_data.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

struct PoseFitOptions {
  int iterations = 12;        // Gauss-Newton iterations (measured converged by 10 on lego)
  int max_cg_iterations = 8;
  double pose_prior = 1e-3;  // relative to the data, as SolverOptions::pose_prior
  ResidualSettings residuals;
};

using PoseValues = std::array<float, kPoseValues>;

// Fits the pose values (PoseParam order, in the box frame of `geometry`) of every view of `views`
// from `start` (one per view) against the volume of shape `volume` (params: its grid, shells and
// spherical harmonics, ShStart() + ShParams values; its exposures and poses are ignored), each
// view's colours taken through transforms[k]. Uses `backend` (its level is replaced). Returns the
// fitted values, one per view.
std::vector<PoseValues> FitViewPoses(Backend* backend, const VolumeShape& volume, std::span<const float> params,
                                     const VolumeGeometry& geometry, const std::vector<PosedImage>& views,
                                     const std::vector<ColourTransform<float>>& transforms,
                                     const std::vector<PoseValues>& start, const PoseFitOptions& options);

}  // namespace perf::recon
