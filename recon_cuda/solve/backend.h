// One interface, two implementations (DESIGN.md "Backends"): the passes over all training rays
// that the solver needs, and the few vector operations of PCG, line search and Adam, on vectors
// the backend owns (host memory for `cpu`, device memory for `cuda`). The solver loop
// (solver.h) is host code written once against this interface.
//
// Passes (DESIGN.md "Gauss-Newton step"):
//   Linearize   cost, g = J^T r and diag(J^T J) at x, for one seed (the jitter of every ray);
//   MultiplyJtJ J^T J p at the last linearisation point and seed, never forming J^T J;
//   Cost        cost only (line search), optionally on a subset of the rays;
//   Render      one camera without jitter.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/comm.h"
#include "recon_cuda/core/smoothness.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/data/volume.h"

namespace perf::recon {

// The residuals (DESIGN.md "One ray" step 5).
struct ResidualSettings {
  float lambda = 0.1f;  // weight of the paper's auxiliary residual L; 0 switches it off
  // Early ray termination: the march stops once the transmittance drops below this. What is
  // behind then contributes less than this fraction to the pixel (and to every partial). 1e-3:
  // 7-11 % fewer samples than 1e-4, held-out PSNR within run-to-run noise (docs/tuning.md
  // "Residuals and rays").
  float stop_transmittance = 1e-3f;
  // Jitter every sample along its ray (DESIGN.md "One ray"); off, samples sit mid-segment and
  // every pass sees the same rays (tests, reference solves).
  bool jitter = true;
  // With jitter, also move each ray to a random point of its pixel every iteration (DESIGN.md
  // "One ray" step 1). Off (rays through pixel centres, the default), a deviation from the
  // design: on, each GN step fits that iteration's sub-pixel noise and scores lower held-out
  // (docs/tuning.md "Residuals and rays").
  bool pixel_jitter = false;
  // Where the rays carry the photos' alpha (RaySet::alphas), the fourth residual fits the box
  // opacity to it instead of the paper's auxiliary term (ray_math.h AuxResidual).
  bool use_alpha = true;
  // The weight of that alpha residual (lambda's counterpart); 0.3 (docs/tuning.md "Residuals and
  // rays").
  float alpha_weight = 0.3f;
  // The colour residuals' robust loss: Cauchy with this scale c (a ray whose colour error |r| is c
  // gets half the weight it has in least squares), solved by reweighting inside Gauss-Newton
  // (jacobian.h RobustRowScale); 0: least squares (the default).
  float robust_scale = 0.f;
};

// Everything a backend needs for one level of the hierarchy.
struct LevelProblem {
  VolumeShape shape;
  VolumeGeometry geometry;
  const RaySet* rays = nullptr;  // must outlive the level; nullptr: a render-only level (no rays)
  ResidualSettings residuals;
  // The shells are constants, not variables: a known background (scene.json's background
  // colour, which RGBA photos were composited over). Solvers leave them where they start.
  bool fixed_shells = false;
  // The photos' pose corrections (VolumeShape::poses) are held where they are at this level:
  // they shape the rays but are not solved (HierarchyOptions::refine_poses_from).
  bool fixed_poses = false;
  // Everything but the pose corrections is held: a fit of the cameras against a frozen volume
  // (run/pose_fit.h).
  bool fixed_volume = false;
  // The photos' focal lengths (PoseParam's value 3) are held at the imported ones
  // (HierarchyOptions::refine_focal is off).
  bool fixed_focal = true;
  // MultiplyJtJ will run on every k-th ray (SolverOptions::jtj_ray_stride): what the CPU
  // backend's Jacobian record is sized for.
  int jtj_ray_stride = 1;
  // The parameters the level starts from ([shape.ParamCount()]), or empty. Only a prediction for
  // the level's plan (the CPU backend's record estimate ends rays where they turn opaque), never
  // solved from: the solver uploads its own start.
  std::span<const float> start = {};
  HeldKinds Held() const { return {fixed_shells, fixed_poses, fixed_volume, fixed_focal}; }
};

// Whether the level's fourth residual is the alpha one (ResidualSettings::use_alpha).
inline bool UsesAlpha(const LevelProblem& p) {
  return p.residuals.use_alpha && p.rays != nullptr && !p.rays->alphas.empty();
}

// The weight of the fourth residual: alpha_weight for the alpha residual (fits_alpha), else lambda.
inline float OpacityResidualWeight(const ResidualSettings& r, bool fits_alpha) {
  return fits_alpha ? r.alpha_weight : r.lambda;
}
inline float OpacityResidualWeight(const LevelProblem& p) { return OpacityResidualWeight(p.residuals, UsesAlpha(p)); }

using VecId = int;
inline constexpr VecId kNoVector = -1;

// Rays i with i % stride == offset (stride 1: all).
struct RaySubset {
  int stride = 1;
  int offset = 0;
  bool Valid() const { return stride >= 1 && offset >= 0 && offset < stride; }
  bool Contains(int64_t i) const { return i % stride == offset; }
  // The first ray of the subset at or after ray i >= 0.
  int64_t FirstFrom(int64_t i) const { return i + ((offset - i % stride) + stride) % stride; }
  // Rays of the subset in [begin, end).
  int64_t CountIn(int64_t begin, int64_t end) const {
    const int64_t first = FirstFrom(begin);
    return first < end ? (end - first + stride - 1) / stride : 0;
  }
};

struct PassStats {
  double cost = 0;        // 0.5 sum of squared residuals (colour and auxiliary)
  double colour_sse = 0;  // sum of squared colour residuals (for PSNR: MSE = colour_sse / (3 rays))
  int64_t rays = 0;       // rays evaluated
  int64_t samples = 0;    // march samples composited (MultiplyJtJ on the CPU's merged record: the rays' cells)
  double seconds = 0;
  // Linearize only: the cost of the rays of its `subset` alone, summed as Cost(x, seed, subset)
  // sums it (the line search's starting cost without a pass of its own).
  double subset_cost = 0;
};

// -10 log10(mse), 99 dB for a perfect match.
inline double PsnrFromMse(double mse) { return mse > 0 ? -10.0 * std::log10(mse) : 99.0; }

struct MemoryEstimate {
  int64_t vectors = 0;        // the solver's parameter vectors
  int64_t scratch = 0;        // per-thread sums and other working memory
  int64_t jacobian_cache = 0; // what MultiplyJtJ reuses from Linearize (0 when recomputing)
  // What a record of every ray would take, where jacobian_cache holds only part of it (the CUDA
  // backend's record where memory is short: the other rays are recomputed); 0: all of it.
  int64_t jacobian_wanted = 0;
  int64_t rays = 0;           // training rays
  int64_t available = 0;      // what the backend may use (free RAM or device memory)
  int64_t Total() const { return vectors + scratch + jacobian_cache + rays; }
  // What the level cannot do without: everything but the Jacobian cache, which a backend short
  // of memory drops (it recomputes).
  int64_t Needed() const { return vectors + scratch + rays; }
  // Whether Needed() fits in what is available (0: unknown, assumed to fit).
  bool Fits() const { return available <= 0 || Needed() <= available; }
};

// Adam, the baseline, compared at its best: CALIBRATION.md's colour rate and a density rate
// re-tuned for our volume (docs/tuning.md).
struct AdamSettings {
  float lr_colour = 0.02f, lr_density = 4.0f, lr_opacity = 0.02f;
  float beta1 = 0.9f, beta2 = 0.999f, epsilon = 1e-8f;
};

// The scalars of Adam step t (from 1) that every element's update shares (param_ops.h).
inline AdamCoefficients AdamCoefficientsAt(const AdamSettings& s, int t) {
  return {s.lr_colour,
          s.lr_density,
          s.lr_opacity,
          s.beta1,
          s.beta2,
          s.epsilon,
          1.f / (1.f - std::pow(s.beta1, static_cast<float>(t))),
          1.f / (1.f - std::pow(s.beta2, static_cast<float>(t)))};
}

struct RenderOutput {
  int width = 0, height = 0;
  std::vector<float> colour;   // [height, width, 3]
  std::vector<float> opacity;  // [height, width]: 1 - T_box, the box's opacity along the ray
};

enum class BackendKind { kCpu, kCuda };

class Backend {
 public:
  virtual ~Backend() = default;

  virtual BackendKind kind() const = 0;
  // "cpu (2 threads)", "cuda (NVIDIA H100 80GB HBM3)".
  virtual std::string Describe() const = 0;

  // What SetLevel would allocate. Pure: allocates nothing.
  virtual MemoryEstimate EstimateMemory(const LevelProblem& problem, int num_vectors) const = 0;
  // Drops the previous level's vectors and caches and allocates `num_vectors` parameter vectors
  // (ids 0 .. num_vectors - 1, zero-filled). Throws ResourceError, naming the level, what it
  // needs and what is available, when it does not fit; returns the estimate it went by.
  virtual MemoryEstimate SetLevel(const LevelProblem& problem, int num_vectors) = 0;
  virtual const LevelProblem& level() const = 0;
  // Whether MultiplyJtJ reuses the partials of Linearize (false: it recomputes them).
  virtual bool CachesJacobian() const = 0;
  // Frees what MultiplyJtJ reuses of the last Linearize (the recorded Jacobian, a level's largest
  // buffer, and the per-thread sums); MultiplyJtJ then needs a Linearize first. The hierarchy calls
  // it when a level's solve is done, so that the level's checkpoint and scores run without it.
  // keep_room: a level follows; the backend may keep the record's memory for it (the CPU backend's
  // merged cells: its pages need no first touch again), given back by the next SetLevel if unused.
  virtual void ReleaseJacobian(bool keep_room) { (void)keep_room; }

  // Vector operations; every vector has level().shape.ParamCount() floats.
  virtual void Upload(VecId v, std::span<const float> host) = 0;
  virtual void Download(VecId v, std::span<float> host) const = 0;
  virtual void Fill(VecId v, float value) = 0;
  virtual void Copy(VecId dst, VecId src) = 0;
  virtual void Axpy(VecId y, double a, VecId x) = 0;  // y += a x
  virtual void Xpby(VecId y, VecId x, double b) = 0;  // y = x + b y
  // z = r / max(d, floor): the Jacobi preconditioner (paper "Preconditioner").
  virtual void DivideClamped(VecId z, VecId r, VecId d, float floor) = 0;
  // y += a (d .* x): Levenberg-Marquardt damping with the diagonal d.
  virtual void AxpyDiag(VecId y, double a, VecId d, VecId x) = 0;
  // Deterministic (independent of the thread count) in double.
  virtual double Dot(VecId a, VecId b) const = 0;
  virtual double MaxAbs(VecId v) const = 0;
  // The same over the volume's entries alone (grid and shells; not the photos' exposures, whose
  // diagonal entries sum a whole photo and would dwarf every other).
  virtual double MaxAbsVolume(VecId v) const = 0;
  // x = valid(x): sigma >= 0, colours and opacities in [0, 1].
  virtual void Project(VecId x) = 0;
  // free = 0 where a parameter is held for this iteration (param_ops.h HeldParameter: a fixed
  // shell of the level's problem; with `bounds`, one at a bound of its range that g points out
  // of), 1 elsewhere; g is zeroed where held.
  virtual void HoldParameters(VecId x, VecId g, VecId free, bool bounds) = 0;
  // y = y .* m (element-wise).
  virtual void Multiply(VecId y, VecId m) = 0;
  // Until the next Linearize, MultiplyJtJ is needed only on the entries where `free` is 1 and for
  // p that is 0 where it is 0 (the reduced system of projected Gauss-Newton). A backend may drop
  // work that then adds exact zeros to those entries (the CPU backend drops recorded samples in
  // empty space whose cells' densities are all held); the entries where free is 1 stay exactly
  // as they were. The CUDA backend skips those samples on the fly (jacobian.h SkippableSample),
  // from its record and where it recomputes.
  virtual void RestrictJacobian(VecId /*free*/) {}
  // z's pose part (VolumeShape::poses) = the photos' 6 x 6 pose blocks of J^T J at the last
  // Linearize, their diagonal replaced by max(diag, floor), solved for r's pose part over the
  // entries where free is 1 (solve/pose_blocks.h), after DivideClamped gave z the Jacobi step.
  // The default keeps the Jacobi step (a backend that keeps no blocks).
  virtual void PreconditionPoses(VecId /*z*/, VecId /*r*/, VecId /*diag*/, VecId /*free*/, float /*floor*/) {}
  // The smoothness term (smoothness.h) with weights w at v: out += L v unless out is kNoVector
  // (out != v), diag += L's diagonal unless diag is kNoVector.
  virtual void AddSmoothness(VecId v, const SmoothnessWeights& w, VecId out, VecId diag) = 0;
  // Its cost at v, v^T L v / 2, deterministic like Dot.
  virtual double SmoothnessCost(VecId v, const SmoothnessWeights& w) const = 0;
  // The sum of v's entries of each ParamKind (indexed by its value), deterministic like Dot.
  virtual std::array<double, kParamKinds> SumByKind(VecId v) const = 0;
  // v = the sum of every rank's v (distributed_backend.h). The default sums a host copy; a
  // backend whose memory the communicator reads (host vectors, NCCL's device memory) sums in place.
  virtual void SumAcrossRanks(VecId v, Communicator& comm);
  // One Adam step (Kingma & Ba) with per-kind learning rates, t = step number from 1.
  virtual void AdamStep(VecId x, VecId g, VecId m, VecId v, const AdamSettings& s, int t) = 0;

  // Passes. `seed` fixes every ray's jitter; the same seed gives the same rays in every pass.
  // g and diag: outputs, or kNoVector to skip (Adam needs no diagonal). subset: the rays whose
  // cost PassStats::subset_cost sums. jtj: the rays MultiplyJtJ multiplies until the next
  // Linearize (subsampled Gauss-Newton; the CPU backend records only their partials).
  virtual PassStats Linearize(VecId x, uint32_t seed, VecId g, VecId diag, RaySubset subset = {},
                              RaySubset jtj = {}) = 0;
  // out = J_S^T J_S p, J_S the rows of the last Linearize's jtj rays at its x and seed (x must not
  // have changed since); not scaled to all rays.
  virtual PassStats MultiplyJtJ(VecId p, VecId out) = 0;
  virtual PassStats Cost(VecId x, uint32_t seed, RaySubset subset = {}) = 0;
  // No jitter; where the box's opacity along a ray is below min_box_opacity the box is treated
  // as empty for that ray (render_rule.h: the paper's 0.7), 0 renders it as is.
  virtual RenderOutput Render(VecId x, const PinholeCamera<float>& camera, int width, int height,
                              float min_box_opacity) = 0;
};

}  // namespace perf::recon
