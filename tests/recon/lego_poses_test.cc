// Camera refinement on real data (issue 31): lego at 50 x 50 with exact poses, and with every
// training pose perturbed (rotation 1 degree about a random axis, centre 2 % of its distance to
// the box centre in a random direction, fixed seed), each reconstructed with and without
// --refine-poses on the CPU (2 levels, 8 Gauss-Newton iterations each, as lego_reconstruct_test).
// Prints every figure; skips without ../shared/data.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>
#include <numbers>
#include <optional>
#include <random>

#include "export/evaluate.h"
#include "recon_cuda/backends/make_backend.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/photo_corrections.h"
#include "recon_cuda/run/pose_fit.h"
#include "recon_cuda/run/reconstruct.h"
#include "sfm_import/importer.h"
#include "tests/test_util.h"
#include "workspace/scene.h"

namespace perf::recon {
namespace {

namespace fs = std::filesystem;

// prior: --pose-prior (unset: the default, which depends on `focal`).
ReconstructResult Fit(const fs::path& workspace, bool refine, bool focal = false,
                      std::optional<double> prior = std::nullopt) {
  ReconstructOptions o;
  o.workspace = workspace;
  o.device = DeviceChoice::kCpu;
  o.levels = 2;
  o.iterations = 8;
  o.solver.cost_tolerance = 0;  // every iteration, with and without refinement alike
  o.poses = refine ? PoseChoice::kOn : PoseChoice::kOff;
  o.refine_focal = focal;
  o.pose_prior = prior;
  return Reconstruct(o);
}

fs::path ImportLego(const fs::path& workspace) {
  ImportOptions io;
  io.nerf_json = test::SharedData("lego") / "transforms_train.json";
  io.workspace = workspace;
  io.downscale = 16;
  RunImport(io);
  return workspace;
}

// Every training camera turned by `degrees` about a random axis through its centre and moved by
// `fraction` of its distance to the box centre in a random direction.
Scene Perturbed(Scene scene, double degrees, double fraction, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n;
  const auto random_unit = [&] {
    Eigen::Vector3d v(n(rng), n(rng), n(rng));
    return Eigen::Vector3d(v.normalized());
  };
  for (SceneImage& im : scene.images) {
    if (im.split != Split::kTrain) continue;
    const Eigen::Matrix3d turn(Eigen::AngleAxisd(degrees * std::numbers::pi / 180, random_unit()));
    const double distance = (im.world_from_cam.col(3) - scene.box.center).norm();
    im.world_from_cam.leftCols<3>() = turn * im.world_from_cam.leftCols<3>();
    im.world_from_cam.col(3) += fraction * distance * random_unit();
  }
  return scene;
}

void Perturb(const fs::path& workspace, double degrees, double fraction, uint32_t seed) {
  WriteScene(workspace / "scene.json", Perturbed(ReadScene(workspace / "scene.json"), degrees, fraction, seed));
}

struct PoseErrors {
  double median_degrees = 0, median_fraction = 0;
  // The median over cameras of the median image distance (pixels) between where the exact and
  // the given camera see 27 points of the box's inner half: what a pose error does to the
  // pictures. A turn about the object with the matching shift (an orbit) moves them least; at
  // 50 x 50 pixels it is the direction the photos pin down least.
  double median_pixels = 0;
  // The same two errors after the similarity (Eigen::umeyama on the centres) that best maps the
  // given cameras onto the exact ones: what is left once the set's drift as a whole (the gauge,
  // held by the prior alone) is taken out, as pose-refining NeRF papers score.
  double aligned_degrees = 0, aligned_fraction = 0;
};

// The training cameras of `got` (refined where it refined them) against the exact ones.
PoseErrors ErrorsAgainst(const Scene& exact, const Scene& got) {
  std::vector<double> degrees, fractions, pixels, aligned_degrees, aligned_fractions;
  std::vector<int> train;
  for (size_t i = 0; i < got.images.size(); ++i) {
    if (got.images[i].split == Split::kTrain) train.push_back(static_cast<int>(i));
  }
  Eigen::Matrix3Xd from(3, train.size()), to(3, train.size());
  for (size_t k = 0; k < train.size(); ++k) {
    const SceneImage& im = got.images[train[k]];
    from.col(k) = im.refined_world_from_cam.value_or(im.world_from_cam).col(3);
    to.col(k) = exact.images[train[k]].world_from_cam.col(3);
  }
  const Eigen::Matrix4d sim = Eigen::umeyama(from, to, true);
  const Eigen::Matrix3d turn = sim.topLeftCorner<3, 3>() / std::cbrt(sim.topLeftCorner<3, 3>().determinant());
  for (size_t i = 0; i < got.images.size(); ++i) {
    const SceneImage& im = got.images[i];
    if (im.split != Split::kTrain) continue;
    const Eigen::Matrix<double, 3, 4> pose = im.refined_world_from_cam.value_or(im.world_from_cam);
    const Eigen::Matrix<double, 3, 4>& truth = exact.images[i].world_from_cam;
    const Eigen::Matrix3d r = truth.leftCols<3>().transpose() * pose.leftCols<3>();
    degrees.push_back(Eigen::AngleAxisd(r).angle() * 180 / std::numbers::pi);
    fractions.push_back((pose.col(3) - truth.col(3)).norm() / (truth.col(3) - exact.box.center).norm());
    const Eigen::Vector3d aligned_centre = sim.topLeftCorner<3, 3>() * pose.col(3) + sim.topRightCorner<3, 1>();
    aligned_degrees.push_back(Eigen::AngleAxisd(truth.leftCols<3>().transpose() * turn * pose.leftCols<3>()).angle() *
                              180 / std::numbers::pi);
    aligned_fractions.push_back((aligned_centre - truth.col(3)).norm() / (truth.col(3) - exact.box.center).norm());
    const SceneCamera& cam = exact.camera(im.camera_id);
    const auto project = [&](const Eigen::Matrix<double, 3, 4>& m, const Eigen::Vector3d& p) {
      const Eigen::Vector3d q = m.leftCols<3>().transpose() * (p - m.col(3));
      return Eigen::Vector2d(cam.fx * q.x() / q.z() + cam.cx, cam.fy * q.y() / q.z() + cam.cy);
    };
    std::vector<double> shifts;
    for (int a = -1; a <= 1; ++a)
      for (int b = -1; b <= 1; ++b)
        for (int c = -1; c <= 1; ++c) {
          const Eigen::Vector3d p =
              exact.box.center + exact.box.rotation * exact.box.size.cwiseProduct(Eigen::Vector3d(a, b, c)) * 0.25;
          shifts.push_back((project(pose, p) - project(truth, p)).norm());
        }
    std::nth_element(shifts.begin(), shifts.begin() + shifts.size() / 2, shifts.end());
    pixels.push_back(shifts[shifts.size() / 2]);
  }
  const auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  return {median(degrees), median(fractions), median(pixels), median(aligned_degrees), median(aligned_fractions)};
}
PoseErrors ErrorsAgainst(const Scene& exact, const fs::path& workspace) {
  return ErrorsAgainst(exact, ReadScene(workspace / "scene.json"));
}

// The test-time fit (pose_fit.h) of the perturbed training cameras against the volume fitted on
// the exact ones: what the data and the model can tell about a camera when the volume is right.
TEST(LegoPoses, ATestTimeFitRecoversCamerasAgainstTheExactVolume) {
  PERF_REQUIRE_DATA(lego, "lego");
  test::TempDir dir;
  const fs::path ws = ImportLego(dir.path() / "exact");
  const ReconstructResult exact_fit = Fit(ws, false);
  const Scene exact = ReadScene(ws / "scene.json");
  const Scene perturbed = Perturbed(exact, 1.0, 0.02, 31);
  const Checkpoint c = ReadCheckpoint(exact_fit.final_checkpoint);
  const VolumeGeometry geometry = GeometryOf(c);
  const std::vector<PosedImage> views = LoadImages(perturbed, ws, Split::kTrain);
  const std::vector<ColourTransform<float>> identity(views.size());
  const std::vector<PoseValues> zeros(views.size(), PoseValues{});
  auto backend = MakeBackend(DeviceChoice::kCpu, 0);
  const std::vector<PoseValues> fitted =
      FitViewPoses(backend.get(), c.shape, c.params, geometry, views, identity, zeros, PoseFitOptions{});
  Scene refined = perturbed;
  int k = 0;
  for (SceneImage& im : refined.images) {
    if (im.split != Split::kTrain) continue;
    double in[12], out[12];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) in[4 * i + j] = im.world_from_cam(i, j);
    CorrectedPose(in, fitted[k++].data(), geometry, out);
    Eigen::Matrix<double, 3, 4> m;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) m(i, j) = out[4 * i + j];
    im.refined_world_from_cam = m;
  }
  const PoseErrors after = ErrorsAgainst(exact, refined);
  const PoseErrors before = ErrorsAgainst(exact, perturbed);
  std::printf("lego 50x50, test-time fit of 100 cameras perturbed by 1 degree and 2 %% against the volume of the "
              "exact ones: median error %.3f deg, %.3f %% of the distance, %.3f px (before: %.3f px)\n",
              after.median_degrees, 100 * after.median_fraction, after.median_pixels, before.median_pixels);
  EXPECT_LT(after.median_pixels, 0.25 * before.median_pixels);
  EXPECT_LT(after.median_degrees, 0.4);
}

// Held-out views are scored as perf eval scores them: the headline takes each view's camera from
// its neighbours' corrections; the test-time fit scores it after fitting its camera alone.
exporter::EvalResult Eval(const fs::path& workspace) {
  exporter::EvalOptions o;
  o.workspace = workspace;
  o.device = DeviceChoice::kCpu;
  o.html = false;
  return exporter::RunEval(o);
}

TEST(LegoPoses, RefinementRecoversPerturbedCamerasAndKeepsExactOnes) {
  PERF_REQUIRE_DATA(lego, "lego");
  test::TempDir dir;
  const Scene exact = ReadScene(ImportLego(dir.path() / "exact") / "scene.json");
  const ReconstructResult exact_off = Fit(dir.path() / "exact", false);
  ImportLego(dir.path() / "exact_on");
  const ReconstructResult exact_on = Fit(dir.path() / "exact_on", true);
  for (const char* name : {"perturbed_off", "perturbed_on"}) {
    ImportLego(dir.path() / name);
    Perturb(dir.path() / name, 1.0, 0.02, 31);
  }
  const ReconstructResult off = Fit(dir.path() / "perturbed_off", false);
  const ReconstructResult on = Fit(dir.path() / "perturbed_on", true);
  const exporter::EvalResult exact_on_eval = Eval(dir.path() / "exact_on");
  const exporter::EvalResult on_eval = Eval(dir.path() / "perturbed_on");
  const PoseErrors before = ErrorsAgainst(exact, dir.path() / "perturbed_off");
  const PoseErrors after = ErrorsAgainst(exact, dir.path() / "perturbed_on");
  const PoseErrors exact_moved = ErrorsAgainst(exact, dir.path() / "exact_on");
  std::printf(
      "lego 50x50, 8 + 8 GN iterations, held-out PSNR (headline; after the test-time pose fit):\n"
      "  exact poses: %.2f dB without refinement; %.2f dB (%.2f) with it, the cameras moving %.3f deg / %.3f %% / "
      "%.3f px\n"
      "  perturbed by 1 deg and 2 %%: %.2f dB without refinement; %.2f dB (%.2f) with it\n"
      "  median pose error: %.3f deg, %.2f %% of the distance, %.3f px before; %.3f deg, %.3f %%, %.3f px after\n"
      "  after aligning the refined set to the exact one (a similarity): %.3f deg, %.3f %%\n"
      "  solve %.0f s without refinement, %.0f s with (perturbed)\n",
      exact_off.test_psnr, exact_on.test_psnr, exact_on_eval.mean_psnr_pose_fit, exact_moved.median_degrees,
      100 * exact_moved.median_fraction, exact_moved.median_pixels, off.test_psnr, on.test_psnr,
      on_eval.mean_psnr_pose_fit, before.median_degrees, 100 * before.median_fraction, before.median_pixels,
      after.median_degrees, 100 * after.median_fraction, after.median_pixels, after.aligned_degrees,
      100 * after.aligned_fraction, off.solve_seconds, on.solve_seconds);
  EXPECT_NEAR(before.median_degrees, 1.0, 1e-6);
  // Measured 2026-12-05 (pose prior 0.03, the default): 1.28 -> 0.30 px, 1.0 -> 0.47 deg, 2.0 ->
  // 0.94 % (prior 0.1: 0.64 deg, 1.09 %); the pictures line up, the orbit direction stays where
  // the prior holds it (the 0.1 deg / 0.3 % are not reached at 50 pixels; docs/tuning.md
  // "Camera refinement"). Held-out after the test-time fit 28.51 dB against 28.30 on exact poses,
  // 20.13 without refinement; exact poses refined 28.29 dB (prior 0.01: 28.10, over the bound).
  EXPECT_LT(after.median_pixels, 0.35 * before.median_pixels);
  EXPECT_LT(after.median_degrees, 0.6 * before.median_degrees);
  EXPECT_LT(after.median_fraction, 0.75 * before.median_fraction);
  EXPECT_TRUE(on_eval.pose_fit);
  EXPECT_GT(on_eval.mean_psnr_pose_fit, exact_off.test_psnr - 0.3);
  EXPECT_GT(on_eval.mean_psnr_pose_fit, off.test_psnr + 1.0);
  EXPECT_GT(exact_on.test_psnr, exact_off.test_psnr - 0.05);
  EXPECT_LT(exact_moved.median_pixels, 0.25);
}

// Each training photo's focal length 3 % too long or too short (its own, fixed seed; a zoom lens
// whose EXIF was ignored), the poses exact: --refine-intrinsics focal with the poses against the
// poses alone. (A focal length off by the same factor for every photo, held-out ones too, costs
// lego at 50 pixels little: 28.24 dB against 28.30 exact, measured 2026-12-03; the volume takes
// the scale. The held-out views keep their exact focal lengths here, so their headline scores
// take the neighbours' corrections as noise, as in the perturbed-pose test above.)
TEST(LegoPoses, FocalRefinementRecoversWrongFocalLengths) {
  PERF_REQUIRE_DATA(lego, "lego");
  test::TempDir dir;
  const double error = 0.03;
  std::vector<double> wrong;  // per image, scene.json order (1 for held-out ones)
  for (const char* name : {"off", "poses", "focal"}) {
    const fs::path ws = ImportLego(dir.path() / name);
    Scene s = ReadScene(ws / "scene.json");
    std::mt19937 rng(33);
    wrong.clear();
    const int first_new = static_cast<int>(s.cameras.size());
    for (SceneImage& im : s.images) {
      const double f = im.split == Split::kTrain ? (rng() % 2 ? 1 + error : 1 - error) : 1.0;
      wrong.push_back(f);
      if (f == 1.0) continue;
      SceneCamera c = s.camera(im.camera_id);
      c.id = first_new + static_cast<int>(wrong.size());
      c.fx *= f;
      c.fy *= f;
      s.cameras.push_back(c);
      im.camera_id = c.id;
    }
    WriteScene(ws / "scene.json", s);
  }
  const ReconstructResult off = Fit(dir.path() / "off", false);
  // Poses alone at the prior focal refinement uses by default, so the two differ by the focal
  // lengths alone (a weaker prior lets the distance absorb more of a focal error: a dolly zoom).
  const ReconstructResult poses = Fit(dir.path() / "poses", true, false, kFocalPosePrior);
  const ReconstructResult focal = Fit(dir.path() / "focal", true, true);
  // The median over training photos of |refined focal / true focal - 1|.
  std::vector<double> errors;
  const Scene refined = ReadScene(dir.path() / "focal" / "scene.json");
  for (size_t i = 0; i < refined.images.size(); ++i) {
    const SceneImage& im = refined.images[i];
    if (im.split == Split::kTrain) errors.push_back(std::abs(wrong[i] * im.refined_focal_scale.value_or(1.0) - 1));
  }
  ASSERT_FALSE(errors.empty());
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  const double median = errors[errors.size() / 2];
  std::printf("lego 50x50, each training photo's focal length 3 %% off, 8 + 8 GN iterations: held-out %.2f dB "
              "without refinement, %.2f dB refining the poses, %.2f dB refining poses and focal lengths (median "
              "focal error %.2f %%, was 3 %%); train PSNR %.2f / %.2f / %.2f dB; solve %.0f / %.0f / %.0f s\n",
              off.test_psnr, poses.test_psnr, focal.test_psnr, 100 * median, off.levels.back().train_psnr,
              poses.levels.back().train_psnr, focal.levels.back().train_psnr, off.solve_seconds, poses.solve_seconds,
              focal.solve_seconds);
  // Measured 2026-12-03: 3 % -> 1.46 %; train PSNR 24.02 / 27.16 / 28.46 dB; held-out 26.52 / 25.95 /
  // 24.39 dB (exact held-out focal lengths take the neighbours' corrections). The rest of the
  // error trades against the camera's distance (a dolly zoom), where the pose prior holds it.
  EXPECT_LT(median, 0.6 * error);
  EXPECT_GT(focal.levels.back().train_psnr, poses.levels.back().train_psnr + 0.5);
}

}  // namespace
}  // namespace perf::recon
