#include "recon_cuda/run/reconstruct_options.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "recon_cuda/data/checkpoint.h"
#include "workspace/scene.h"

namespace perf::recon {
namespace {

void Fail(const char* option, const std::string& value, const std::string& problem, const std::string& hint = {}) {
  throw InputError("command line", option, value, problem, hint);
}

}  // namespace

SolverOptions ReconstructOptions::DefaultSolver() {
  SolverOptions s;
  s.smooth_grid = -1;  // chosen for the scene (Hierarchy)
  s.smooth_shells = 0.1;
  s.cost_tolerance = kDefaultCostTolerance;
  return s;
}

void ReconstructOptions::Check() const {
  if (workspace.empty()) Fail("WORKSPACE", "", "missing", "pass the workspace made by perf import");
  if (levels < 0 || levels > 6) Fail("--levels", std::to_string(levels), "must be 1 to 6 (or 0 for the default)");
  if (!std::isfinite(solver.smooth_grid)) Fail("--smooth-grid", StrCat(solver.smooth_grid), "must be finite (0: off)");
  CheckShDegree(sh_degree);
  if (max_resolution != 0 && max_resolution < start_resolution) {
    Fail("--max-resolution", std::to_string(max_resolution), StrCat("must be at least --start-resolution (", start_resolution, ")"),
         "or 0 for the backend's default");
  }
  if (start_resolution < 2 || start_resolution > 1024) {
    Fail("--start-resolution", std::to_string(start_resolution), "must be 2 to 1024");
  }
  if (max_resolution > kMaxGridSize) {
    Fail("--max-resolution", std::to_string(max_resolution), StrCat("must be at most ", kMaxGridSize));
  }
  if (levels > 0 && (int64_t{start_resolution} << (levels - 1)) > kMaxGridSize) {
    Fail("--levels", std::to_string(levels),
         StrCat("the finest level would be ", int64_t{start_resolution} << (levels - 1), "^3, more than ", kMaxGridSize,
                "^3"),
         "use fewer levels or a smaller --start-resolution");
  }
  if (iterations < 0) Fail("--iterations", std::to_string(iterations), "must be >= 0");
  for (int i : level_iterations) {
    if (i < 0) Fail("--level-iterations", std::to_string(i), "must be >= 0 for every level");
  }
  if (preview_every < 0) Fail("--preview-every", std::to_string(preview_every), "must be >= 0");
  if (poses == PoseChoice::kOn && solver.type == SolverType::kAdam) {
    Fail("--refine-poses", "on", "refines poses in Gauss-Newton only", "use --solver gn, or --refine-poses off");
  }
  CheckCameraRefinement(poses, refine_focal);
  CheckShFromLevel(sh_from_level);
  if (refine_poses_from < 1 || refine_poses_from > 6) {
    Fail("--refine-poses-from", std::to_string(refine_poses_from), "must be a level, 1 (the first) to 6");
  }
  if (eval_every < 0) Fail("--eval-every", std::to_string(eval_every), "must be >= 0");
  if (!(residuals.lambda >= 0 && std::isfinite(residuals.lambda))) {
    Fail("--lambda", StrCat(residuals.lambda), "must be finite and >= 0 (0: off)");
  }
  if (!(residuals.alpha_weight >= 0 && std::isfinite(residuals.alpha_weight))) {
    Fail("--alpha-weight", StrCat(residuals.alpha_weight), "must be finite and >= 0 (0: off)");
  }
  if (!(residuals.robust_scale >= 0 && std::isfinite(residuals.robust_scale))) {
    Fail("--robust", StrCat(residuals.robust_scale), "must be >= 0 (0: least squares)");
  }
  if (!(residuals.stop_transmittance >= 0 && residuals.stop_transmittance < 1)) {
    Fail("--stop-transmittance", StrCat(residuals.stop_transmittance), "must be in [0, 1)");
  }
  if (!(init.box_opacity >= 0 && init.box_opacity < 1)) {
    Fail("--init-opacity", StrCat(init.box_opacity), "must be in [0, 1)", "0.99 is the default; 0.05 a nearly clear start");
  }
  if (!(min_box_opacity >= 0 && min_box_opacity <= 1)) {
    Fail("--min-box-opacity", StrCat(min_box_opacity), "must be in [0, 1]");
  }
  SolverOptions chosen = solver;  // the automatic grid weight is valid whatever it becomes
  chosen.smooth_grid = std::max(0.0, chosen.smooth_grid);
  chosen.pose_prior = PosePrior();  // checked as the solver will see it
  chosen.Check();
}

HierarchyOptions ReconstructOptions::Hierarchy(const Scene& scene, const LevelChoice& choice) const {
  HierarchyOptions h;
  h.levels = choice.levels;
  h.stop_when_out_of_memory = choice.automatic;
  h.start_resolution = start_resolution;
  h.iterations = iterations;
  h.level_iterations = level_iterations;
  h.solver = solver;
  h.init = init;
  h.residuals = residuals;
  h.pyramid = pyramid;
  h.sparse = !dense;
  h.occupancy = occupancy;
  h.sh_degree = sh_degree;
  h.sh_from_level = ShFromLevelIndex(sh_from_level, choice);
  SetHierarchyBackground(background, scene, &h);
  if (h.solver.smooth_grid < 0) h.solver.smooth_grid = h.fixed_background ? 0.0 : kAutoSmoothGrid;
  if (solver.type == SolverType::kAdam) h.solver.smooth_grid = h.solver.smooth_shells = 0;  // Gauss-Newton only
  const int train = static_cast<int>(SplitViews(scene, Split::kTrain).size());
  h.exposures = SolvesExposures(exposure, scene) ? train : 0;
  h.poses = RefinesPoses(poses, scene, solver.type) ? train : 0;
  h.refine_poses_from = refine_poses_from - 1;
  if (refine_focal && h.poses == 0) {
    Fail("--refine-intrinsics", "focal",
         StrCat("refines the focal length with the poses, which this run does not refine (--refine-poses auto "
                "refines them for COLMAP photos with Gauss-Newton; this scene is from ",
                scene.source.type, ")"),
         "add --refine-poses on");
  }
  h.refine_focal = refine_focal;
  h.solver.pose_prior = PosePrior();
  return h;
}

double ReconstructOptions::PosePrior() const {
  return pose_prior.value_or(refine_focal ? kFocalPosePrior : kDefaultPosePrior);
}

bool FixedBackground(BackgroundChoice background, const Scene& scene) {
  return background == BackgroundChoice::kAuto ? EveryImageHasAlpha(scene) : background == BackgroundChoice::kFixed;
}

void CheckShDegree(int sh_degree) {
  if (sh_degree < 0 || sh_degree > 2) Fail("--sh-degree", std::to_string(sh_degree), "must be 0, 1 or 2");
}

void CheckShFromLevel(int sh_from_level) {
  if (sh_from_level < -5 || sh_from_level > 6) {
    Fail("--sh-from-level", std::to_string(sh_from_level),
         "must be a level, 1 (the first) to 6, or counted from the last: 0 (the last), -1 (the last two) to -5");
  }
}

int ShFromLevelIndex(int sh_from_level, const LevelChoice& choice) {
  const int last = choice.levels - 1;
  if (sh_from_level <= 0) return std::max(0, last + sh_from_level);  // the last levels, or all there are
  if (sh_from_level > choice.levels && !choice.automatic) {
    Fail("--sh-from-level", std::to_string(sh_from_level),
         StrCat("is past the last of the ", choice.levels, " levels: no level would solve the bands"),
         StrCat("use 1 to ", choice.levels, ", or 0 for the last level"));
  }
  return std::min(sh_from_level - 1, last);  // levels from the photos: at most their last
}

void CheckCameraRefinement(PoseChoice poses, bool refine_focal) {
  if (refine_focal && poses == PoseChoice::kOff) {
    Fail("--refine-intrinsics", "focal", "refines the focal length with the poses", "add --refine-poses on");
  }
}

bool SolvesExposures(ExposureChoice exposure, const Scene& scene) {
  return exposure == ExposureChoice::kOn || (exposure == ExposureChoice::kAuto && scene.source.type == "colmap");
}

bool RefinesPoses(PoseChoice poses, const Scene& scene, SolverType solver) {
  if (solver != SolverType::kGaussNewton) return false;
  return poses == PoseChoice::kOn || (poses == PoseChoice::kAuto && scene.source.type == "colmap");
}

void SetHierarchyBackground(BackgroundChoice background, const Scene& scene, HierarchyOptions* options) {
  options->fixed_background = FixedBackground(background, scene);
  options->background = {static_cast<float>(scene.background.x()), static_cast<float>(scene.background.y()),
                         static_cast<float>(scene.background.z())};
}

}  // namespace perf::recon
