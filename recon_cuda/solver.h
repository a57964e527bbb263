// The solver of one level (paper "Gauss-Newton solver" .. "Line search"; DESIGN.md
// "Gauss-Newton step"), in Ceres' shape: Options with documented defaults and Check(), a Summary
// with a status, costs, per-phase timings and BriefReport(), and Solve(). Host code written once
// against backend.h, so the CPU and CUDA backends share it.
//
// Gauss-Newton iteration:
//   1. Linearize at x: cost, g = J^T r, D = diag(J^T J), one jitter seed for the whole iteration;
//   2. PCG (paper Algorithm 2) on (J^T J + mu D) d = -g from d = 0, Jacobi preconditioner D,
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
#include <vector>

#include "recon_cuda/backend.h"

namespace perf::recon {

enum class SolverType { kGaussNewton, kAdam };
const char* SolverName(SolverType t);

struct SolverOptions {
  SolverType type = SolverType::kGaussNewton;
  // Gauss-Newton iterations, or Adam steps, at this level (paper: 30 per level).
  int max_iterations = 30;
  // Jitter: iteration k uses Hash(seed, k, 0) for every pass (DESIGN.md "Gauss-Newton step").
  uint32_t seed = 1;

  // PCG (paper Algorithm 2). The paper leaves after 1-3 iterations through its ratio test
  // (cg_exit_ratio 0.85). Here that test stopped CG after 2 iterations in most GN steps, and
  // running 6 regardless was clearly better per second on lego 50x50 (32^3 + 64^3, CPU):
  //   ratio 0.85, at most 3 (mostly 2): 8 + 8 GN 24.77 dB in 29 s, 16 + 16 25.43 dB in 70 s;
  //   ratio 1.0, at most 6:             8 + 8 GN 25.34 dB in 30 s;
  //   no ratio exit, 4 / 6 / 10:        8 + 8 GN 25.56 / 25.82 / 25.91 dB in 36 / 41 / 62 s,
  //                                     6 + 6 GN with 6: 25.83 dB in 32 s.
  // (Those were scored with the paper's render rule, render_rule.h. Scored as fitted, with the
  // alpha weight 0.3 and the restricted J^T J p: the paper's exit 28.01 dB in 22 s, 6 CG 8 + 8
  // 28.36 dB in 29 s, 6 + 6 28.32 dB in 22 s, 16 + 16 28.42 dB in 51 s.)
  // (Before the active set, longer CG overshot, as CALIBRATION.md also saw.) On the bonsai
  // example 6 gave -0.1 dB over the whole view and +0.8 dB inside the mask at 8 + 8.
  int max_cg_iterations = 6;
  // Leave when |r_k+1|^2 / |r_k|^2 > this (the paper: 0.85). CG's residual need not fall
  // monotonically, so values above 1 tolerate a rise; infinity (the default) runs
  // max_cg_iterations (or to cg_relative_tolerance).
  double cg_exit_ratio = std::numeric_limits<double>::infinity();
  double cg_relative_tolerance = 1e-10;  // or when |r|^2 < this |r_0|^2
  // Levenberg-Marquardt style damping: solves (J^T J + damping D) d = -g. 0: plain Gauss-Newton.
  double damping = 0.0;
  // Preconditioner floor relative to the largest diagonal entry. Besides guarding parameters no
  // ray reaches, it holds back the steps of those the rays barely constrain (the colour of a
  // nearly clear cell), which otherwise overshoot and are clamped. Measured on lego 50x50
  // (8 + 8 GN): 1e-9 22.43 dB, 1e-5 22.63, 1e-4 22.73, 1e-3 21.75, 1e-2 21.0; again with held
  // bounds, a fixed background and centred rays (no opacity residual): 1e-5 24.42, 1e-4 24.88,
  // 1e-3 24.72 dB.
  double diagonal_floor = 1e-4;

  // Projected Gauss-Newton: leave the parameters at a bound of their range whose gradient
  // points out of it (sigma = 0 with g > 0, a colour at 0 or 1 pushed further) out of the
  // iteration's CG system, instead of letting the step move them and the projection undo it.
  // On lego 50x50 (8 + 8 GN, every other default) three quarters of the parameters are held by
  // the last iterations, and held-out PSNR goes from 25.47 to 28.36 dB. CG's J^T J p then skips
  // the samples that reach only held densities (backend.h RestrictJacobian).
  bool hold_at_bounds = true;

  // Line search (paper Algorithm 3).
  double initial_step = 1.0;
  double step_factor = 0.7;
  int max_line_search_steps = 8;
  // Evaluate the line search's costs on every k-th ray only (1: all rays). 4 measured the same
  // held-out PSNR as 1 on lego (50x50, 8 + 8 iterations: 22.43 dB both) at half the line
  // search's time (3DGS-LM uses 30 % of the images likewise).
  int line_search_ray_stride = 4;

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
  kNoProgress,      // 3 consecutive Gauss-Newton steps were rejected by the line search
  kUserAbort,       // the iteration callback asked to stop
  kFailure,         // the cost became non-finite (diverged or bad input values)
};
const char* StatusName(SolverStatus s);

struct IterationSummary {
  int iteration = 0;          // 0-based within the level
  double cost = 0;            // at the start of the iteration (its rays and jitter)
  double cost_after = 0;      // after the accepted step (line search rays)
  double train_psnr = 0;      // on the fixed subset after the step; 0 when off
  int cg_iterations = 0;
  int64_t held = 0;           // parameters left out of the step (fixed shells, at a bound)
  double step = 0;            // accepted gamma (0: rejected; Adam: 1)
  int line_search_steps = 0;  // cost evaluations in the line search
  bool accepted = true;
  double seconds_linearize = 0, seconds_cg = 0, seconds_line_search = 0, seconds_update = 0,
         seconds_psnr = 0, seconds_total = 0;
  int64_t samples = 0;        // march samples of the Linearize pass
};

struct SolverSummary {
  SolverStatus status = SolverStatus::kIterationLimit;
  double initial_cost = 0, final_cost = 0;
  int iterations = 0;
  std::vector<IterationSummary> per_iteration;
  double seconds_linearize = 0, seconds_cg = 0, seconds_line_search = 0, seconds_update = 0, seconds_psnr = 0,
         seconds_total = 0;
  int linearize_passes = 0, jtj_passes = 0, cost_passes = 0;
  std::string message;

  // One line: "GN: 8 iterations, cost 1.2e3 -> 4.5e1, 9.8 s (linearize 3.1, cg 2.5, line search 3.6), iteration limit".
  std::string BriefReport() const;
};

// Return false to stop after this iteration (status kUserAbort).
using IterationCallback = std::function<bool(const IterationSummary&)>;

// Runs the solver from `x` (host copy, ParamCount values, in the valid range) on the backend's
// current level and writes the result back into `x`. The backend must have had SetLevel called
// with at least RequiredVectors(type) vectors.
void Solve(const SolverOptions& options, Backend* backend, std::vector<float>* x, const IterationCallback& callback,
           SolverSummary* summary);

int RequiredVectors(SolverType type);

// The backend vector that holds x during and after Solve (for renders from a callback).
inline constexpr VecId kSolverX = 0;
// Gauss-Newton: the backend vector holding the last iteration's PCG step d (before the line
// search scales it), for inspection after Solve.
inline constexpr VecId kSolverStep = 3;

}  // namespace perf::recon
