#include "recon_cuda/run/pose_fit.h"

#include "common/errors.h"
#include "recon_cuda/solve/solver.h"

namespace perf::recon {

std::vector<PoseValues> FitViewPoses(Backend* backend, const VolumeShape& volume, std::span<const float> params,
                                     const VolumeGeometry& geometry, const std::vector<PosedImage>& views,
                                     const std::vector<ColourTransform<float>>& transforms,
                                     const std::vector<PoseValues>& start, const PoseFitOptions& options) {
  const int n = static_cast<int>(views.size());
  PERF_CHECK(static_cast<int>(transforms.size()) == n && static_cast<int>(start.size()) == n);
  if (n == 0) return {};
  const VolumeShape shape = volume.WithExposures(n).WithPoses(n);
  const int64_t volume_params = volume.ExposureStart();
  PERF_CHECK(static_cast<int64_t>(params.size()) >= volume_params);
  std::vector<float> x(params.begin(), params.begin() + volume_params);
  for (const ColourTransform<float>& xf : transforms) {
    for (int c = 0; c < 4; ++c) x.push_back(c < 3 ? xf.gain[c] - 1 : 0.f);
    for (int c = 0; c < 4; ++c) x.push_back(c < 3 ? xf.offset[c] : 0.f);
  }
  for (const PoseValues& p : start) x.insert(x.end(), p.begin(), p.end());
  PERF_CHECK(static_cast<int64_t>(x.size()) == shape.ParamCount());

  const RaySet rays = MakeRaySet(views);  // view k in slot k
  LevelProblem problem{shape, geometry, &rays, options.residuals, true};
  problem.fixed_volume = true;
  SolverOptions so;
  so.max_iterations = options.iterations;
  so.max_cg_iterations = options.max_cg_iterations;
  so.smooth_grid = so.smooth_shells = 0;
  so.exposure_prior = 0;
  so.pose_prior = options.pose_prior;
  so.line_search_ray_stride = 1;
  so.psnr_ray_stride = 0;
  backend->SetLevel(problem, RequiredVectors(so.type));
  SolverSummary summary;
  Solve(so, backend, &x, nullptr, &summary);
  if (summary.status == SolverStatus::kFailure) throw Error(StrCat("the pose fit failed: ", summary.message));
  std::vector<PoseValues> out(n);
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < kPoseValues; ++j) out[k][j] = x[PoseParam(shape.PoseStart(), k) + j];
  }
  return out;
}

}  // namespace perf::recon
