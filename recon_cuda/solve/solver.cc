#include "recon_cuda/solve/solver.h"

#include <cmath>
#include <cstdio>
#include <limits>

#include "common/errors.h"
#include "common/stopwatch.h"

namespace perf::recon {
namespace {

// Vector ids of the Gauss-Newton solver.
// kFree: 1 for the parameters that are variables of this iteration, 0 for held ones.
// Three share a vector, each free when the next takes it (7 parameter vectors instead of 10, which
// at bonsai's 128^3 level with view dependence is 120 MiB): PCG's residual starts as -g (kG is not
// read again in the iteration), its preconditioned residual z lives in kAp between J^T J p's
// (A p is spent once the residual and step have it), and the line search's trial point in kAp too.
enum : VecId { kX, kG, kDiag, kStep, kDir, kAp, kFree, kGnVectors };
constexpr VecId kResidual = kG, kZ = kAp, kTrial = kAp;
// Adam reuses kX and kG; its moments and free mask live in three more.
enum : VecId { kAdamM = 2, kAdamV = 3, kAdamFree = 4, kAdamVectors = 5 };

void Fail(const char* field, const std::string& value, const std::string& problem) {
  throw InputError("solver options", field, value, problem);
}

double Psnr(double colour_sse, int64_t rays) {
  return rays > 0 ? PsnrFromMse(colour_sse / (3.0 * static_cast<double>(rays))) : 0.0;
}

// Gauss-Newton's convergence test (SolverOptions::cost_tolerance) after the iterations so far:
// the cost at the newest one's start against the cost cost_tolerance_window iterations before.
bool Converged(const SolverOptions& o, const std::vector<IterationSummary>& done) {
  const int w = o.cost_tolerance_window, n = static_cast<int>(done.size());
  if (o.type != SolverType::kGaussNewton || o.cost_tolerance <= 0 || n <= w) return false;
  const double now = done[n - 1].cost, before = done[n - 1 - w].cost;
  return before - now < o.cost_tolerance * now;
}

}  // namespace

const char* SolverName(SolverType t) { return t == SolverType::kGaussNewton ? "gn" : "adam"; }

const char* StatusName(SolverStatus s) {
  switch (s) {
    case SolverStatus::kIterationLimit: return "iteration limit";
    case SolverStatus::kConverged: return "converged";
    case SolverStatus::kNoProgress: return "no progress";
    case SolverStatus::kUserAbort: return "stopped by the caller";
    case SolverStatus::kPlanned: return "ended by the time plan";
    case SolverStatus::kFailure: return "failure";
  }
  return "?";
}

int RequiredVectors(SolverType type) {
  return type == SolverType::kGaussNewton ? static_cast<int>(kGnVectors) : static_cast<int>(kAdamVectors);
}

SolverVectors VectorsOf(SolverType type) {
  SolverVectors v;
  v.params = kX;
  if (type == SolverType::kGaussNewton) v.last_step = kStep;
  for (VecId i = 0; i < RequiredVectors(type); ++i) {
    if (i != kX) v.scratch.push_back(i);
  }
  return v;
}

void SolverOptions::Check() const {
  if (max_iterations < 0) Fail("max_iterations", std::to_string(max_iterations), "must be >= 0");
  if (max_cg_iterations < 1) Fail("max_cg_iterations", std::to_string(max_cg_iterations), "must be >= 1");
  if (!(cg_exit_ratio > 0)) Fail("cg_exit_ratio", StrCat(cg_exit_ratio), "must be > 0");
  if (!(damping >= 0 && std::isfinite(damping))) Fail("damping (--damping)", StrCat(damping), "must be finite and >= 0");
  if (!(initial_step > 0 && std::isfinite(initial_step))) {
    Fail("initial_step (--initial-step)", StrCat(initial_step), "must be finite and > 0");
  }
  if (!(diagonal_floor > 0 && std::isfinite(diagonal_floor))) {
    Fail("diagonal_floor (--diagonal-floor)", StrCat(diagonal_floor), "must be finite and > 0 (default 1e-4)");
  }
  if (!(step_factor > 0 && step_factor < 1)) Fail("step_factor", StrCat(step_factor), "must be in (0, 1)");
  if (max_line_search_steps < 1) Fail("max_line_search_steps", std::to_string(max_line_search_steps), "must be >= 1");
  if (line_search_ray_stride < 1) Fail("line_search_ray_stride", std::to_string(line_search_ray_stride), "must be >= 1");
  if (jtj_ray_stride < 1 || jtj_ray_stride > 64) {
    Fail("jtj_ray_stride (--jtj-ray-stride)", std::to_string(jtj_ray_stride), "must be 1 to 64");
  }
  // Weights relative to the photos: beyond kMaxRelativeWeight their squares swamp the photos'
  // residuals and overflow float sums ("cost is not finite" later, naming nothing).
  const auto check_weight = [](const char* name, double w) {
    if (!(w >= 0 && w <= kMaxRelativeWeight)) {
      Fail(name, StrCat(w), StrCat("must be a number from 0 to ", kMaxRelativeWeight, " (relative to the photos)"));
    }
  };
  check_weight("pose_prior (--pose-prior)", pose_prior);
  check_weight("exposure_prior (--exposure-prior)", exposure_prior);
  check_weight("smooth_grid (--smooth-grid)", smooth_grid);
  check_weight("smooth_shells (--smooth-shells)", smooth_shells);
  if (!(cost_tolerance >= 0 && cost_tolerance < 1)) {
    Fail("cost_tolerance (--cost-tolerance)", StrCat(cost_tolerance), "must be in [0, 1) (0: off)");
  }
  if (cost_tolerance_window < 1) {
    Fail("cost_tolerance_window", std::to_string(cost_tolerance_window), "must be >= 1");
  }
  if (psnr_ray_stride < 0) Fail("psnr_ray_stride", std::to_string(psnr_ray_stride), "must be >= 0");
  const auto finite_positive = [](float v) { return v > 0 && std::isfinite(v); };
  if (!(finite_positive(adam.lr_colour) && finite_positive(adam.lr_density) && finite_positive(adam.lr_opacity))) {
    Fail("adam learning rates (--lr-colour, --lr-density)",
         StrCat(adam.lr_colour, ", ", adam.lr_density, ", ", adam.lr_opacity), "must be finite and > 0");
  }
}

nlohmann::json IterationSummary::ToJson() const {
  return {{"iteration", iteration},
          {"cost", cost},
          {"cost_after", cost_after},
          {"train_psnr", train_psnr},
          {"cg_iterations", cg_iterations},
          {"held", held},
          {"step", step},
          {"line_search_steps", line_search_steps},
          {"accepted", accepted},
          {"samples", samples},
          {"seconds",
           {{"linearize", seconds_linearize},
            {"cg", seconds_cg},
            {"line_search", seconds_line_search},
            {"update", seconds_update},
            {"psnr", seconds_psnr},
            {"total", seconds_total}}}};
}

nlohmann::json SolverSummary::ToJson() const {
  return {{"status", StatusName(status)},
          {"iterations", iterations},
          {"initial_cost", initial_cost},
          {"final_cost", final_cost},
          {"phase_seconds",
           {{"linearize", seconds_linearize},
            {"cg", seconds_cg},
            {"line_search", seconds_line_search},
            {"update", seconds_update},
            {"psnr", seconds_psnr},
            {"total", seconds_total}}},
          {"passes", {{"linearize", linearize_passes}, {"jtj_p", jtj_passes}, {"cost", cost_passes}}},
          {"smoothness_weights",
           {{"grid_colour", smoothness.grid_colour},
            {"grid_density", smoothness.grid_density},
            {"shell_colour", smoothness.shell_colour},
            {"shell_opacity", smoothness.shell_opacity},
            {"exposure", smoothness.exposure},
            {"pose_rotation", smoothness.pose_rotation},
            {"pose_centre", smoothness.pose_centre},
            {"pose_focal", smoothness.pose_focal}}},
          {"report", BriefReport()}};
}

std::string SolverSummary::BriefReport() const {
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "%d iterations, cost %.6g -> %.6g, %.2f s (linearize %.2f, cg %.2f, line search %.2f, update %.2f, "
                "psnr %.2f), %d+%d+%d passes, %s",
                iterations, initial_cost, final_cost, seconds_total, seconds_linearize, seconds_cg, seconds_line_search,
                seconds_update, seconds_psnr, linearize_passes, jtj_passes, cost_passes, StatusName(status));
  return buf;
}

namespace {

// The pair weights of the smoothness term (SolverOptions::smooth_grid, smooth_shells) from the
// data's diagonal D of the level's first linearisation: relative weight times D's mean per kind.
SmoothnessWeights CalibrateSmoothness(const SolverOptions& o, Backend* b) {
  SmoothnessWeights w;
  const VolumeShape& shape = b->level().shape;
  const bool exposures = shape.exposures > 0 && o.exposure_prior > 0;
  const bool poses = shape.poses > 0 && o.pose_prior > 0;
  if (o.smooth_grid <= 0 && o.smooth_shells <= 0 && !exposures && !poses) return w;
  const std::array<double, kParamKinds> sums = b->SumByKind(kDiag);
  const double cells = static_cast<double>(shape.StoredCells());
  const double texels = static_cast<double>(shape.ShellTexels());
  const auto mean = [&](ParamKind k, double count) { return count > 0 ? sums[static_cast<int>(k)] / count : 0.0; };
  w.grid_colour = static_cast<float>(o.smooth_grid * mean(ParamKind::kGridColour, 3 * cells));
  w.grid_density = static_cast<float>(o.smooth_grid * mean(ParamKind::kGridDensity, cells));
  if (!b->level().fixed_shells) {  // constants: nothing to smooth
    w.shell_colour = static_cast<float>(o.smooth_shells * mean(ParamKind::kShellColour, 3 * texels));
    w.shell_opacity = static_cast<float>(o.smooth_shells * mean(ParamKind::kShellOpacity, texels));
  }
  if (exposures) w.exposure = static_cast<float>(o.exposure_prior * mean(ParamKind::kExposureGain, 3.0 * shape.exposures));
  if (poses) {
    w.pose_rotation = static_cast<float>(o.pose_prior * mean(ParamKind::kPoseRotation, 3.0 * shape.poses));
    w.pose_centre = static_cast<float>(o.pose_prior * mean(ParamKind::kPoseCentre, 3.0 * shape.poses));
    w.pose_focal = static_cast<float>(o.pose_prior * mean(ParamKind::kPoseFocal, 1.0 * shape.poses));
  }
  return w;
}

// PCG (paper Algorithm 2) on (J^T J + mu D) d = -g, d = 0 at the start. Returns iterations.
// J includes the smoothness residuals of weights w (their J^T J is the Laplacian).
int SolvePcg(const SolverOptions& o, Backend* b, const SmoothnessWeights& w, SolverSummary* summary) {
  b->Fill(kStep, 0.f);
  b->Axpy(kResidual, -2.0, kG);  // r0 = b - A 0 = -g, in g's own vector (g - 2 g: exact)
  const double floor = std::max(o.diagonal_floor * b->MaxAbsVolume(kDiag), 1e-30);
  const bool poses = b->level().shape.poses > 0;
  b->DivideClamped(kZ, kResidual, kDiag, static_cast<float>(floor));
  if (poses) b->PreconditionPoses(kZ, kResidual, kDiag, kFree, static_cast<float>(floor));
  b->Copy(kDir, kZ);
  double rz = b->Dot(kResidual, kZ);
  double r_prev = b->Dot(kResidual, kResidual);
  const double r0 = r_prev;
  int k = 0;
  while (k < o.max_cg_iterations) {
    b->MultiplyJtJ(kDir, kAp);  // overwrites z (kZ = kAp): dir holds what is needed of it
    if (o.jtj_ray_stride > 1) b->Axpy(kAp, o.jtj_ray_stride - 1, kAp);  // the subset's product, scaled to all rays
    if (w.Any()) b->AddSmoothness(kDir, w, kAp, kNoVector);
    b->Multiply(kAp, kFree);  // the system of the free parameters only
    ++summary->jtj_passes;
    if (o.damping > 0) b->AxpyDiag(kAp, o.damping, kDiag, kDir);
    const double pap = b->Dot(kDir, kAp);
    if (!(pap > 0)) break;  // no curvature along p (p = 0 or numerically flat)
    const double alpha = rz / pap;
    b->Axpy(kStep, alpha, kDir);
    b->Axpy(kResidual, -alpha, kAp);
    ++k;
    const double r = b->Dot(kResidual, kResidual);
    if (r < o.cg_relative_tolerance * r0 || r / r_prev > o.cg_exit_ratio || k == o.max_cg_iterations) break;
    r_prev = r;
    b->DivideClamped(kZ, kResidual, kDiag, static_cast<float>(floor));
    if (poses) b->PreconditionPoses(kZ, kResidual, kDiag, kFree, static_cast<float>(floor));
    const double rz_next = b->Dot(kResidual, kZ);
    b->Xpby(kDir, kZ, rz_next / rz);
    rz = rz_next;
  }
  return k;
}

// The smoothness term's cost at v (0 when off).
double SmoothnessCost(Backend* b, VecId v, const SmoothnessWeights& w) {
  return w.Any() ? b->SmoothnessCost(v, w) : 0.0;
}

// x(gamma) = P(x + gamma d) into kTrial.
void TrialPoint(Backend* b, double gamma) {
  b->Copy(kTrial, kX);
  b->Axpy(kTrial, gamma, kStep);
  b->Project(kTrial);
}

}  // namespace

void Solve(const SolverOptions& o, Backend* b, std::vector<float>* x, const IterationCallback& callback,
           SolverSummary* summary) {
  o.Check();
  *summary = SolverSummary();
  const auto t_solve = WallClock::now();
  PERF_CHECK(static_cast<int64_t>(x->size()) == b->level().shape.ParamCount());
  b->Upload(kX, *x);
  if (o.type == SolverType::kAdam) {
    b->Fill(kAdamM, 0.f);
    b->Fill(kAdamV, 0.f);
  }
  int rejected_in_a_row = 0;
  const RaySubset ls_subset{o.line_search_ray_stride, 0};
  for (int it = 0; it < o.max_iterations; ++it) {
    IterationSummary s;
    s.iteration = it;
    const auto t_it = WallClock::now();
    const uint32_t seed = Hash(o.seed, static_cast<uint32_t>(it), 0u);

    auto t0 = WallClock::now();
    // Subsampled Gauss-Newton: J^T J p on every jtj_ray_stride-th ray, a different share each iteration.
    const RaySubset jtj{o.jtj_ray_stride, it % o.jtj_ray_stride};
    PassStats lin =
        b->Linearize(kX, seed, kG, o.type == SolverType::kGaussNewton ? kDiag : kNoVector, ls_subset, jtj);
    ++summary->linearize_passes;
    if (o.type == SolverType::kGaussNewton) {
      if (it == 0) summary->smoothness = CalibrateSmoothness(o, b);
      if (summary->smoothness.Any()) {
        const double e = b->SmoothnessCost(kX, summary->smoothness);
        b->AddSmoothness(kX, summary->smoothness, kG, kDiag);
        lin.cost += e;
        lin.subset_cost += e / o.line_search_ray_stride;  // on the subset's scale, as the line search sees it
      }
    }
    s.seconds_linearize = SecondsSince(t0);
    s.cost = lin.cost;
    s.samples = lin.samples;
    if (!std::isfinite(lin.cost)) {
      summary->status = SolverStatus::kFailure;
      summary->message = StrCat("the cost is not finite at iteration ", it);
      break;
    }
    if (it == 0) summary->initial_cost = lin.cost;

    if (o.type == SolverType::kAdam) {
      t0 = WallClock::now();
      if (b->level().fixed_shells) {
        b->HoldParameters(kX, kG, kAdamFree, false);
        s.held = b->level().shape.ParamCount() - std::llround(b->Dot(kAdamFree, kAdamFree));
      }
      b->AdamStep(kX, kG, kAdamM, kAdamV, o.adam, it + 1);
      s.seconds_update = SecondsSince(t0);
      s.step = 1;
      s.cost_after = lin.cost;  // of the step's own pass: Adam evaluates nothing else
    } else {
      t0 = WallClock::now();
      b->HoldParameters(kX, kG, kFree, o.hold_at_bounds);
      b->RestrictJacobian(kFree);
      b->Multiply(kDiag, kFree);  // the reduced system's diagonal (and the floor's reference)
      s.held = b->level().shape.ParamCount() - std::llround(b->Dot(kFree, kFree));
      s.cg_iterations = SolvePcg(o, b, summary->smoothness, summary);
      s.seconds_cg = SecondsSince(t0);

      t0 = WallClock::now();
      const double cost0 = lin.subset_cost;  // the line search's rays at x, from the linearisation
      // Paper Algorithm 3: shrink while the cost keeps falling; take the last gamma before it rose.
      double gamma = o.initial_step, best_gamma = 0, best = std::numeric_limits<double>::infinity();
      double prev = std::numeric_limits<double>::infinity();
      for (int k = 0; k < o.max_line_search_steps; ++k) {
        TrialPoint(b, gamma);
        const double mu = b->Cost(kTrial, seed, ls_subset).cost + SmoothnessCost(b, kTrial, summary->smoothness) /
                                                                         o.line_search_ray_stride;
        ++summary->cost_passes;
        ++s.line_search_steps;
        if (!(mu <= prev)) break;  // rose (or NaN): the previous gamma was the best
        prev = best = mu;
        best_gamma = gamma;
        gamma *= o.step_factor;
      }
      s.seconds_line_search = SecondsSince(t0);

      t0 = WallClock::now();
      s.accepted = best < cost0;
      if (s.accepted) {
        b->Axpy(kX, best_gamma, kStep);
        b->Project(kX);
        s.step = best_gamma;
        s.cost_after = best;
        rejected_in_a_row = 0;
      } else {
        s.step = 0;
        s.cost_after = cost0;
        ++rejected_in_a_row;
      }
      s.seconds_update = SecondsSince(t0);
      if (o.line_search_ray_stride > 1) {
        // Report the cost on all rays' scale.
        s.cost_after *= cost0 > 0 ? lin.cost / cost0 : 1.0;
      }
    }

    if (o.psnr_ray_stride > 0) {
      t0 = WallClock::now();
      const PassStats p = b->Cost(kX, 0x5eed5eedu, RaySubset{o.psnr_ray_stride, 0});
      s.train_psnr = Psnr(p.colour_sse, p.rays);
      s.seconds_psnr = SecondsSince(t0);
    }
    s.seconds_total = SecondsSince(t_it);
    summary->seconds_linearize += s.seconds_linearize;
    summary->seconds_cg += s.seconds_cg;
    summary->seconds_line_search += s.seconds_line_search;
    summary->seconds_update += s.seconds_update;
    summary->seconds_psnr += s.seconds_psnr;
    summary->final_cost = s.cost_after;
    summary->iterations = it + 1;
    summary->per_iteration.push_back(s);
    if (callback && !callback(s)) {
      summary->status = SolverStatus::kUserAbort;
      break;
    }
    if (rejected_in_a_row >= 3) {
      summary->status = SolverStatus::kNoProgress;
      summary->message = "3 Gauss-Newton steps in a row did not lower the cost";
      break;
    }
    if (it + 1 < o.max_iterations && Converged(o, summary->per_iteration)) {
      summary->status = SolverStatus::kConverged;
      summary->message = StrCat("the cost fell by less than ", o.cost_tolerance * 100, " % in ",
                                o.cost_tolerance_window, " iterations");
      break;
    }
  }
  // The line search saw a subset of the rays: the final cost is measured on all of them, at the
  // last iteration's jitter, so that it and initial_cost (a full Linearize) are on one footing.
  if (o.type == SolverType::kGaussNewton && o.line_search_ray_stride > 1 && summary->iterations > 0 &&
      summary->status != SolverStatus::kFailure) {
    const uint32_t seed = Hash(o.seed, static_cast<uint32_t>(summary->iterations - 1), 0u);
    summary->final_cost = b->Cost(kX, seed).cost + SmoothnessCost(b, kX, summary->smoothness);
    ++summary->cost_passes;
  }
  b->Download(kX, *x);
  summary->seconds_total = SecondsSince(t_solve);
}

}  // namespace perf::recon
