// The solver of one level (paper "Gauss-Newton solver" .. "Line search"; DESIGN.md
// "Gauss-Newton step"), in Ceres' shape: Options with documented defaults and Check(), a Summary
// with a status, costs, per-phase timings and BriefReport(), and Solve(). Host code written once
// against backend.h, so the CPU and CUDA backends share it.
//
// Gauss-Newton iteration:
//   1. Linearize at x: cost, g = J^T r, D = diag(J^T J), one jitter seed for the whole iteration;
//   2. PCG (paper Algorithm 2) on (J^T J + mu D) d = -g from d = 0, Jacobi preconditioner D (each
//      refined photo's 6 pose values: its block of J^T J, Backend::PreconditionPoses),
//      leaving after max_cg_iterations or, with the paper's exit (cg_exit_ratio), when
//      R / R_prev exceeds the ratio (R = |r|^2); restricted to the free parameters: fixed shells
//      and (hold_at_bounds) those at a bound that g points out of keep d = 0 (param_ops.h
//      HeldParameter);
//   3. backtracking line search (paper Algorithm 3) on x(gamma) = P(x + gamma d), P the
//      projection to the valid range: gamma = 1, 0.7, 0.49, ... while the cost keeps falling;
//   4. x = x(gamma) if that lowers the cost, else the step is rejected.
// Adam (the paper's figure 1 baseline): one Linearize without diagonal per step, fresh jitter.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <nlohmann/json.hpp>
#include <vector>

#include "recon_cuda/solve/backend.h"

namespace perf::recon {

enum class SolverType { kGaussNewton, kAdam };
const char* SolverName(SolverType t);

// The largest prior or smoothness weight SolverOptions::Check accepts (relative to the photos).
inline constexpr double kMaxRelativeWeight = 1e6;

struct SolverOptions {
  SolverType type = SolverType::kGaussNewton;
  // Gauss-Newton iterations, or Adam steps, at this level (paper: 30 per level).
  int max_iterations = 30;
  // Gauss-Newton leaves the level (status kConverged) once its cost fell by less than this
  // fraction over the last cost_tolerance_window iterations (Ceres' function_tolerance, over a
  // window since each iteration's cost has its own jitter). 0: always run max_iterations.
  double cost_tolerance = 0;
  int cost_tolerance_window = 4;
  // Jitter: iteration k uses Hash(seed, k, 0) for every pass (DESIGN.md "Gauss-Newton step").
  uint32_t seed = 1;

  // PCG (paper Algorithm 2) iterations per GN step: 6 without the paper's ratio exit, better
  // per second than the paper's 1-3 (docs/tuning.md).
  int max_cg_iterations = 6;
  // Leave when |r_k+1|^2 / |r_k|^2 > this (the paper: 0.85). CG's residual need not fall
  // monotonically, so values above 1 tolerate a rise; infinity (the default) runs
  // max_cg_iterations (or to cg_relative_tolerance).
  double cg_exit_ratio = std::numeric_limits<double>::infinity();
  double cg_relative_tolerance = 1e-10;  // or when |r|^2 < this |r_0|^2
  // Levenberg-Marquardt style damping: solves (J^T J + damping D) d = -g. 0: plain Gauss-Newton.
  double damping = 0.0;
  // Preconditioner floor relative to the largest diagonal entry: guards parameters no ray reaches
  // and holds back barely constrained ones, which otherwise overshoot (docs/tuning.md "Solver").
  double diagonal_floor = 1e-4;

  // Projected Gauss-Newton: parameters at a bound of their range whose gradient points out of it
  // stay out of the iteration's CG system (and J^T J p skips samples reaching only held
  // densities, backend.h RestrictJacobian). On by default: by the last iterations most parameters
  // sit at a bound, and leaving them in the system costs held-out PSNR (docs/tuning.md "Solver").
  bool hold_at_bounds = true;

  // Line search (paper Algorithm 3).
  double initial_step = 1.0;
  double step_factor = 0.7;
  int max_line_search_steps = 8;
  // Evaluate the line search's costs on every k-th ray only (1: all rays); 4 scores as 1 at half
  // the line search's time (docs/tuning.md).
  int line_search_ray_stride = 4;
  // Subsampled Gauss-Newton: PCG's J^T J p on every k-th ray only (a different k-th each
  // iteration), scaled by k; the gradient, diagonal and line search keep all rays. 1: exact.
  int jtj_ray_stride = 1;

  // Smoothness residuals (smoothness.h) between neighbouring grid cells and between neighbouring
  // shell texels, relative to the data: a kind's pair weight is this times the mean of
  // diag(J^T J) over that kind's parameters at the level's first linearisation, so 1 makes a
  // pair as stiff as the average parameter's photos. 0: off. Gauss-Newton only.
  double smooth_grid = 0, smooth_shells = 0;
  // The photos' exposures' prior (smoothness.h), relative to the data as the smoothness weights
  // are: this times the mean of diag(J^T J) over the gains, i.e. 1 holds a gain as firmly as a
  // whole photo's pixels do. Fixes the gauge; 1 measured best of 0.01 to 10 (docs/tuning.md).
  double exposure_prior = 1.0;
  // The photos' pose corrections' prior toward the imported poses (smoothness.h), relative to the
  // data likewise: this times the mean of diag(J^T J) over the rotations (the centres), so 1
  // holds a pose as firmly as the average photo's pixels do, and a correction the photos pin
  // down is shrunk by 1 / (1 + this). Fixes the gauge (every camera moving with the volume).
  // perf reconstruct's default: reconstruct_options.h kDefaultPosePrior.
  double pose_prior = 0.03;

  AdamSettings adam;

  // PSNR of the colour residuals on a fixed subset of the training rays (every k-th ray, a
  // fixed jitter), after each iteration; 0 switches it off.
  int psnr_ray_stride = 16;

  // Throws InputError (file "options") naming the bad field.
  void Check() const;
};

// Why Solve returned.
enum class SolverStatus {
  kIterationLimit,  // max_iterations ran (the normal end: the hierarchy uses a fixed budget)
  kConverged,       // the cost fell by less than cost_tolerance over cost_tolerance_window iterations
  kNoProgress,      // 3 consecutive Gauss-Newton steps were rejected by the line search
  kUserAbort,       // the iteration callback asked to stop
  kPlanned,         // the hierarchy's time plan ended the level (HierarchyCallbacks::end_level)
  kFailure,         // the cost became non-finite (diverged or bad input values)
};
const char* StatusName(SolverStatus s);

struct IterationSummary {
  int iteration = 0;          // 0-based within the level
  double cost = 0;            // at the start of the iteration (its rays and jitter)
  double cost_after = 0;      // after the accepted step (line-search subset, scaled to all rays)
  double train_psnr = 0;      // on the fixed subset after the step; 0 when off
  int cg_iterations = 0;
  int64_t held = 0;           // parameters left out of the step (fixed shells, at a bound)
  double step = 0;            // accepted gamma (0: rejected; Adam: 1)
  int line_search_steps = 0;  // cost evaluations in the line search
  bool accepted = true;
  double seconds_linearize = 0, seconds_cg = 0, seconds_line_search = 0, seconds_update = 0,
         seconds_psnr = 0, seconds_total = 0;
  int64_t samples = 0;        // march samples of the Linearize pass

  // The log's record of the iteration: these fields, the timings under "seconds".
  nlohmann::json ToJson() const;
};

struct SolverSummary {
  SolverStatus status = SolverStatus::kIterationLimit;
  // The cost on all rays at the start and at the end (Gauss-Newton with a line-search subset
  // measures the end with one more Cost pass).
  double initial_cost = 0, final_cost = 0;
  int iterations = 0;
  std::vector<IterationSummary> per_iteration;
  double seconds_linearize = 0, seconds_cg = 0, seconds_line_search = 0, seconds_update = 0, seconds_psnr = 0,
         seconds_total = 0;
  int linearize_passes = 0, jtj_passes = 0, cost_passes = 0;
  SmoothnessWeights smoothness;  // the pair weights the level ran with (all 0: off)
  std::string message;

  // One line: "8 iterations, cost 1.2e+03 -> 45, 9.80 s (linearize 3.10, cg 2.50, line search 3.60,
  // update 0.10, psnr 0.20), 8+48+20 passes, iteration limit".
  std::string BriefReport() const;
  // The record of a level's solve: status, iterations, costs, "phase_seconds", "passes",
  // "smoothness_weights" and "report" (BriefReport).
  nlohmann::json ToJson() const;
};

// Return false to stop after this iteration (status kUserAbort).
using IterationCallback = std::function<bool(const IterationSummary&)>;

// Runs the solver from `x` (host copy, ParamCount values, in the valid range) on the backend's
// current level and writes the result back into `x`. The backend must have had SetLevel called
// with at least RequiredVectors(type) vectors.
void Solve(const SolverOptions& options, Backend* backend, std::vector<float>* x, const IterationCallback& callback,
           SolverSummary* summary);

int RequiredVectors(SolverType type);

// Where Solve keeps its state among the backend's first RequiredVectors(type) vectors.
struct SolverVectors {
  VecId params = 0;              // x, during and after Solve (render or score it from a callback)
  VecId last_step = kNoVector;   // Gauss-Newton: the last PCG step d, before the line search scaled it
  std::vector<VecId> scratch;    // the others: free once Solve has returned
};
SolverVectors VectorsOf(SolverType type);

}  // namespace perf::recon
