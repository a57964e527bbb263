#include "recon_cuda/solve/hierarchy.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"

namespace perf::recon {

VolumeShape LevelShape(const HierarchyOptions& o, int num_shells, int level) {
  return VolumeShape{o.start_resolution << level, o.start_resolution << level, num_shells, nullptr, o.exposures,
                     o.ShDegreeAt(level), o.poses};
}

int ShellResolution(int ladder, int64_t rays, int num_shells, double min_rays_per_texel) {
  if (min_rays_per_texel <= 0 || num_shells <= 0) return ladder;
  const double fit = std::sqrt(static_cast<double>(rays) / (min_rays_per_texel * 6.0 * num_shells));
  const int floor = std::min(ladder, 8);
  return std::max(floor, std::min(ladder, static_cast<int>(fit)));
}

VolumeShape NextLevelShape(const HierarchyOptions& o, const VolumeGeometry& geometry, const VolumeShape& shape,
                           std::span<const float> x, std::span<const ViewFrustum> views, int next_level) {
  const VolumeShape next =
      shape.Doubled().WithExposures(o.exposures).WithShDegree(o.ShDegreeAt(next_level)).WithPoses(o.poses);
  if (!o.sparse || next.n % kBrickSide != 0) return next;
  return next.WithBricks(OccupiedBricks(shape, geometry, x, next.n, o.occupancy, views));
}

int LevelDownscale(const HierarchyOptions& o, std::span<const ViewFrustum> views, const VolumeGeometry& geometry, int n,
                   int level) {
  return o.pyramid ? PyramidFactor(views, geometry, n, 1 << (o.levels - 1 - level)) : 1;
}

std::vector<float> SolveHierarchy(Backend* backend, const VolumeGeometry& geometry, const TrainingViews& train,
                                  const HierarchyOptions& o, HierarchyStart start, const HierarchyCallbacks& cb) {
  std::vector<float> x = std::move(start.x);
  VolumeShape shape = x.empty() ? LevelShape(o, geometry.num_shells(), start.level) : start.shape;
  PERF_CHECK(static_cast<int64_t>(x.size()) == (x.empty() ? 0 : shape.ParamCount()));
  std::vector<float> fitted;  // with stop_when_out_of_memory: the level before's solution
  for (int level = start.level; level < o.levels; ++level) {
    if (cb.before_level && !cb.before_level(level)) break;
    HierarchyLevel h;
    h.level = level;
    h.levels = o.levels;
    h.image_downscale = LevelDownscale(o, train.views, geometry, shape.n, level);
    const RaySet rays = train.rays(h.image_downscale);
    h.rays = rays.size();
    // Shells no finer than this level's rays can pin down.
    const int m = ShellResolution(shape.m, h.rays, shape.num_shells, o.min_rays_per_texel);
    if (m != shape.m) {
      const VolumeShape coarser = shape.WithShellResolution(m);
      if (!x.empty()) x = Resample(shape, x, coarser);
      shape = coarser;
    }
    h.shape = shape;
    if (x.empty()) {  // level 0 of a fresh start
      x = InitialParams(h.shape, geometry, o.init);
      if (o.fixed_background) SetBackgroundShells(h.shape, o.background.data(), x);
    }
    ResidualSettings residuals = o.residuals;
    if (level < o.robust_from_level) residuals.robust_scale = 0.f;
    LevelProblem problem{h.shape, geometry, &rays, residuals, o.fixed_background};
    problem.fixed_poses = level < o.refine_poses_from;
    problem.fixed_focal = !o.refine_focal;
    problem.jtj_ray_stride = o.solver.jtj_ray_stride;
    problem.start = x;
    if (o.stop_when_out_of_memory && level > 0) {
      h.memory = backend->EstimateMemory(problem, RequiredVectors(o.solver.type));
      if (!h.memory.Fits()) {
        if (cb.out_of_memory) cb.out_of_memory(h);
        x = std::move(fitted);
        break;
      }
    }
    h.memory = backend->SetLevel(problem, RequiredVectors(o.solver.type));
    h.solver = o.solver;
    h.solver.max_iterations = o.IterationsAt(level);
    h.solver.seed = Hash(o.init.seed, static_cast<uint32_t>(level), 0x1e7e1u);
    h.params = VectorsOf(o.solver.type).params;
    if (cb.level_started) cb.level_started(h);

    bool stopped = false, ended = false;
    SolverSummary summary;
    Solve(h.solver, backend, &x,
          [&](const IterationSummary& s) {
            stopped = cb.iteration && !cb.iteration(h, s);
            ended = !stopped && cb.end_level && cb.end_level(h, s);
            return !stopped && !ended;
          },
          &summary);
    if (ended && summary.status == SolverStatus::kUserAbort) summary.status = SolverStatus::kPlanned;
    if (summary.status == SolverStatus::kFailure) {
      throw Error(StrCat("level ", level, ": the solver failed: ", summary.message,
                         "; check the workspace images, or try --damping 0.1"));
    }
    // Not needed for what follows (the level's checkpoint, scores, next level); its room may stay
    // for the next level's record.
    backend->ReleaseJacobian(/*keep_room=*/!stopped && level + 1 < o.levels);
    if (cb.level_done) cb.level_done(h, summary, x);
    if (stopped) break;
    if (level + 1 < o.levels) {
      shape = NextLevelShape(o, geometry, h.shape, x, train.views, level + 1);
      std::vector<float> next = Resample(h.shape, x, shape);
      if (o.stop_when_out_of_memory) fitted = std::move(x);
      x = std::move(next);
    }
  }
  // The room kept for a level that did not follow (before_level or the memory check ended the run).
  backend->ReleaseJacobian(/*keep_room=*/false);
  return x;
}

}  // namespace perf::recon
