// The host-side volume: level-to-level resampling (exact for constant and linear fields),
// the random start, the valid-range projection, and placement from scene.json.
#include "recon_cuda/data/volume.h"
#include "recon_cuda/core/pose.h"
#include "recon_cuda/run/photo_corrections.h"

#include <gtest/gtest.h>

#include <cmath>

#include "common/errors.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/run/reconstruct.h"
#include "workspace/scene.h"

namespace perf::recon {
namespace {

// Per-channel linear functions of the cell (texel) centre in box (face) units [0, 1], in the
// middle of the valid range so the projection after resampling does not touch them.
double GridField(double x, double y, double z, int ch) { return 0.4 + 0.1 * x - 0.05 * y + 0.08 * z + 0.02 * ch; }
double FaceField(double u, double v, int shell, int face, int ch) {
  return 0.3 + 0.2 * u - 0.1 * v + 0.05 * shell + 0.01 * face + 0.02 * ch;
}

std::vector<float> LinearVolume(const VolumeShape& s) {
  std::vector<float> x(s.ParamCount());
  for (int k = 0; k < s.n; ++k)
    for (int j = 0; j < s.n; ++j)
      for (int i = 0; i < s.n; ++i)
        for (int ch = 0; ch < 4; ++ch)
          x[GridParam(GridCell(s.n, i, j, k), ch)] =
              static_cast<float>(GridField((i + 0.5) / s.n, (j + 0.5) / s.n, (k + 0.5) / s.n, ch));
  for (int sh = 0; sh < s.num_shells; ++sh)
    for (int f = 0; f < 6; ++f)
      for (int v = 0; v < s.m; ++v)
        for (int u = 0; u < s.m; ++u)
          for (int ch = 0; ch < 4; ++ch)
            x[ShellParam(s.n, s.m, sh, f, u, v, ch)] =
                static_cast<float>(FaceField((u + 0.5) / s.m, (v + 0.5) / s.m, sh, f, ch));
  return x;
}

TEST(VolumeTest, ResamplingKeepsALinearFieldExactly) {
  const VolumeShape from{4, 3, 2};
  const VolumeShape to = from.Doubled();
  EXPECT_EQ(to, (VolumeShape{8, 6, 2}));
  const std::vector<float> out = Resample(from, LinearVolume(from), to);
  const std::vector<float> want = LinearVolume(to);
  ASSERT_EQ(out.size(), want.size());
  for (size_t i = 0; i < out.size(); ++i) ASSERT_NEAR(out[i], want[i], 1e-6) << i;  // border cells included
}

TEST(VolumeTest, ResamplingKeepsAConstantFieldExactly) {
  const VolumeShape from{3, 2, 1};
  std::vector<float> x(from.ParamCount());
  for (size_t i = 0; i < x.size(); ++i) x[i] = i % 4 == 3 ? 0.75f : 0.25f;
  for (const VolumeShape& to : {from.Doubled(), VolumeShape{5, 7, 1}, VolumeShape{1, 1, 1}}) {
    const std::vector<float> out = Resample(from, x, to);
    for (size_t i = 0; i < out.size(); ++i) ASSERT_EQ(out[i], i % 4 == 3 ? 0.75f : 0.25f) << i;
  }
}

TEST(VolumeTest, ResamplingProjectsExtrapolatedValues) {
  // A steep ramp extrapolates below 0 and above 1 at the borders; the result stays valid.
  const VolumeShape from{2, 2, 1};
  std::vector<float> x(from.ParamCount(), 0.5f);
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j) {
      x[GridParam(GridCell(2, 0, j, k), 0)] = 0.f;
      x[GridParam(GridCell(2, 1, j, k), 0)] = 1.f;
      x[GridParam(GridCell(2, 0, j, k), 3)] = 0.f;
      x[GridParam(GridCell(2, 1, j, k), 3)] = 4.f;
    }
  const VolumeShape to = from.Doubled();
  const std::vector<float> out = Resample(from, x, to);
  EXPECT_EQ(out[GridParam(GridCell(4, 0, 0, 0), 0)], 0.f);  // would be -0.25
  EXPECT_EQ(out[GridParam(GridCell(4, 3, 0, 0), 0)], 1.f);  // would be 1.25
  EXPECT_EQ(out[GridParam(GridCell(4, 0, 0, 0), 3)], 0.f);  // sigma >= 0
  EXPECT_FLOAT_EQ(out[GridParam(GridCell(4, 3, 0, 0), 3)], 5.f);  // no upper bound on sigma
  EXPECT_FLOAT_EQ(out[GridParam(GridCell(4, 1, 0, 0), 0)], 0.25f);
}

TEST(VolumeTest, InitialParamsAreRandomValidAndFaint) {
  VolumeGeometry g;
  g.box = {{0, 0, 0}, {{1, 0, 0, 0, 1, 0, 0, 0, 1}}, {2, 3, 4}};
  g.shell_radii = {3, 9};
  const VolumeShape s{16, 8, 2};
  InitOptions o;
  o.box_opacity = 0.2;
  const std::vector<float> x = InitialParams(s, g, o);
  double sigma = 0, colour = 0, opacity = 0;
  int64_t nsig = 0, ncol = 0, nop = 0;
  for (int64_t i = 0; i < s.ParamCount(); ++i) {
    ASSERT_GE(x[i], 0.f);
    switch (KindOf(s, i)) {
      case ParamKind::kGridDensity: sigma += x[i]; ++nsig; break;
      case ParamKind::kShellOpacity: opacity += x[i]; ++nop; break;
      default: ASSERT_LE(x[i], 1.f); colour += x[i]; ++ncol; break;
    }
  }
  // Mean optical depth across the shortest side (2) gives the asked opacity.
  EXPECT_NEAR(1 - std::exp(-sigma / nsig * 2), 0.2, 0.01);
  EXPECT_NEAR(colour / ncol, 0.5, 0.01);
  EXPECT_NEAR(opacity / nop, 0.1, 0.01);
  EXPECT_EQ(InitialParams(s, g, o), x);  // seeded
  o.seed = 2;
  EXPECT_NE(InitialParams(s, g, o), x);
  // A given shell colour (--init-shells-mean) sets every shell texel's colour, nothing else.
  o.shell_colour[0] = 0.9f, o.shell_colour[1] = 0.8f, o.shell_colour[2] = 0.7f;
  const std::vector<float> y = InitialParams(s, g, o);
  for (int64_t i = s.GridParamCount(); i < s.ParamCount(); ++i) {
    if (KindOf(s, i) == ParamKind::kShellColour) {
      ASSERT_EQ(y[i], o.shell_colour[i % 4]) << i;
    }
  }
  // A fixed background: every texel opaque in that colour; the grid as before.
  InitOptions random_shells = o;
  for (float& c : random_shells.shell_colour) c = -1;
  std::vector<float> z = InitialParams(s, g, random_shells);
  SetBackgroundShells(s, o.shell_colour, z);
  for (int64_t i = 0; i < s.ParamCount(); ++i) {
    const ParamKind k = KindOf(s, i);
    if (k == ParamKind::kShellOpacity) {
      ASSERT_EQ(z[i], 1.f) << i;
    } else {
      ASSERT_EQ(z[i], y[i]) << i;
    }
  }
}

// The photos' exposures (ray_types.h ExposureParam): they start at the identity, carry over to
// the next level as they are, and are kept in their range (gain 0.5 to 2, offset +-0.5).
TEST(VolumeTest, ExposuresStartAtTheIdentityCarryOverAndStayInRange) {
  VolumeGeometry g;
  g.box.size = {1, 1, 1};
  g.box.world_from_box = {{1, 0, 0, 0, 1, 0, 0, 0, 1}};
  g.shell_radii = {2, 4};
  const VolumeShape s(4, 2, 2, nullptr, 3);
  EXPECT_EQ(s.ParamCount(), ParamCount(4, 2, 2) + 3 * kExposureValues);
  EXPECT_EQ(s.ExposureStart(), ParamCount(4, 2, 2));
  std::vector<float> x = InitialParams(s, g, {});
  for (int64_t i = s.ExposureStart(); i < s.ParamCount(); ++i) EXPECT_EQ(x[i], 0.f) << i;
  const int64_t e = ExposureParam(s.ExposureStart(), 1);
  EXPECT_EQ(KindOf(s, e), ParamKind::kExposureGain);
  EXPECT_EQ(KindOf(s, e + 4), ParamKind::kExposureOffset);
  EXPECT_EQ(KindOf(s, s.ExposureStart() - 1), ParamKind::kShellOpacity);
  x[e] = 5.f;       // a gain of 6
  x[e + 1] = 0.2f;  // 1.2
  x[e + 4] = -0.7f;
  x[e + 5] = 0.1f;
  ProjectToValidRange(s, x);
  EXPECT_EQ(x[e], 1.f);
  EXPECT_EQ(x[e + 1], 0.2f);
  EXPECT_EQ(x[e + 4], -0.5f);
  EXPECT_EQ(x[e + 5], 0.1f);
  const VolumeShape next = s.Doubled();
  EXPECT_EQ(next.exposures, 3);
  const std::vector<float> y = Resample(s, x, next);
  EXPECT_TRUE(std::equal(x.begin() + s.ExposureStart(), x.end(), y.begin() + next.ExposureStart(), y.end()));
  EXPECT_NE(DescribeShape(s).find("exposures of 3 photos"), std::string::npos) << DescribeShape(s);
}

// A view's exposure outside the solve (exposure.h): the inverse-distance blend of the two
// training photos nearest its camera centre; at a training photo's own centre, that photo's.
TEST(VolumeTest, AViewTakesTheBlendOfItsTwoNearestPhotosExposures) {
  const VolumeShape s(2, 1, 1, nullptr, 3);
  std::vector<float> x(s.ParamCount(), 0.f);
  const float gains[3] = {0.f, 0.2f, -0.3f}, offsets[3] = {0.f, 0.1f, 0.f};
  std::vector<ViewFrustum> views(3);
  for (int k = 0; k < 3; ++k) {
    views[k].camera.world_from_cam[3] = 2.f * k;  // centres at x = 0, 2, 4
    for (int c = 0; c < 3; ++c) {
      x[ExposureParam(s.ExposureStart(), k) + c] = gains[k];
      x[ExposureParam(s.ExposureStart(), k) + 4 + c] = offsets[k];
    }
  }
  const PhotoCorrections e(s, x, views, VolumeGeometry{});
  PinholeCamera<float> at{};
  at.world_from_cam[3] = 0.5f;  // 0.5 from photo 0, 1.5 from photo 1: weights 2 and 2/3
  ColourTransform<float> xf = e.TransformFor(at);
  EXPECT_NEAR(xf.gain[1], (2 * 1.0 + 2.0 / 3 * 1.2) / (2 + 2.0 / 3), 1e-6);
  EXPECT_NEAR(xf.offset[2], (2.0 / 3 * 0.1) / (2 + 2.0 / 3), 1e-6);
  at.world_from_cam[3] = 4.f;  // photo 2's own centre
  xf = e.TransformFor(at);
  EXPECT_FLOAT_EQ(xf.gain[0], 0.7f);
  RenderOutput r;
  r.colour = {0.5f, 0.5f, 0.5f};
  ApplyTransform(e.TransformFor(views[1].camera), &r);
  EXPECT_FLOAT_EQ(r.colour[0], 1.2f * 0.5f + 0.1f);
  EXPECT_TRUE(PhotoCorrections().empty());
  EXPECT_FLOAT_EQ(PhotoCorrections().TransformFor(at).gain[0], 1.f);
}

TEST(VolumeTest, GeometryFromSceneAndItsErrors) {
  Scene scene;
  scene.box.center = {1, 2, 3};
  scene.box.size = {2, 2, 4};
  scene.box.rotation << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  scene.shells.center = {1, 3, 3};
  scene.shells.radii = {3, 6, 12};
  const VolumeGeometry g = VolumeGeometry::FromScene(scene);
  EXPECT_EQ(g.num_shells(), 3);
  // Box-local shell centre: R^T (0, 1, 0) = (1, 0, 0).
  EXPECT_NEAR(g.shell_center.x, 1, 1e-6);
  EXPECT_NEAR(g.shell_center.y, 0, 1e-6);
  EXPECT_EQ(g.box.world_from_box.m[1], -1.f);
  scene.shells.radii.assign(kMaxShells + 1, 1.0);
  EXPECT_THROW(VolumeGeometry::FromScene(scene), InputError);
  scene.shells.radii = {3};
  scene.box.size = {2, 0, 4};
  try {
    VolumeGeometry::FromScene(scene);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "box.size");
  }
}

TEST(VolumeTest, DescribeShape) {
  EXPECT_EQ(DescribeShape({32, 32, 4}), "32^3 grid, 4 shells of 6 x 32^2 texels (229376 parameters)");
  EXPECT_EQ(DescribeShape({128, 128, 1}), "128^3 grid, 1 shell of 6 x 128^2 texels (8.78 M parameters)");
  std::vector<uint8_t> active(64, 0);
  active[5] = active[6] = 1;
  const VolumeShape sparse{32, 32, 4, std::make_shared<const BrickGrid>(MakeBrickGrid(32, active))};
  // 2 bricks x 512 cells x 4 + 4 shells x 6 x 32^2 texels x 4.
  EXPECT_EQ(DescribeShape(sparse), "32^3 grid (2 of 64 bricks), 4 shells of 6 x 32^2 texels (102400 parameters)");
}

// Cameras 4 units from the box centre with fx 100 (and one at 8, one at 2): the box's shortest
// side, 2 units, spans 50 pixels in the median view.
TEST(VolumeTest, PixelsAcrossTheBox) {
  VolumeGeometry g;
  g.box.center = {1, 2, 3};
  g.box.size = {3, 2, 5};
  g.box.world_from_box = {{1, 0, 0, 0, 1, 0, 0, 0, 1}};
  std::vector<ViewFrustum> cams;
  for (float d : {4.f, 8.f, 4.f, 2.f, 4.f}) {
    cams.push_back({{100, 100, 50, 50, {1, 0, 0, 1 + d, 0, 1, 0, 2, 0, 0, 1, 3}}, 100, 100});
  }
  EXPECT_NEAR(PixelsAcrossBox(cams, g), 50.0, 1e-4);
  EXPECT_EQ(PixelsAcrossBox({}, g), 0.0);
}

// A refined camera (photo_corrections.h CorrectedCamera) shoots the rays that ApplyPose gives the
// imported one, and a view between two refined cameras takes the blend of their corrections.
TEST(VolumeTest, ACorrectedCameraShootsThePosedRays) {
  VolumeGeometry g;
  const float c = 0.6f, s = 0.8f;
  g.box = {{0.2f, -0.1f, 0.05f}, {{c, 0, -s, 0, 1, 0, s, 0, c}}, {2.0f, 1.6f, 1.4f}};
  const PinholeCamera<float> cam{40, 42, 16, 12, {0.8f, 0.f, -0.6f, 3.f, 0.f, 1.f, 0.f, -0.5f, 0.6f, 0.f, 0.8f, 1.f}};
  const float pose[kPoseValues] = {0.03f, -0.02f, 0.05f, 0.04f, 0.04f, 0.01f, -0.03f, 0};
  const PinholeCamera<float> moved = CorrectedCamera(cam, pose, g);
  VolumeView<float> vol{};
  vol.n = 8;
  vol.size = g.box.size;
  const Jitter none{0, 0, false, false};
  for (const auto& [px, py] : {std::pair{0, 0}, std::pair{31, 5}, std::pair{12, 23}}) {
    BoxRay<float> want = PixelBoxRay(cam, g.box, vol.n, px, py, none);
    ApplyPose(vol, pose, BoxForward(cam, g.box), &want);
    const BoxRay<float> got = PixelBoxRay(moved, g.box, vol.n, px, py, none);
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(got.origin[a], want.origin[a], 1e-5f);
      EXPECT_NEAR(got.dir[a], want.dir[a], 1e-5f);
      EXPECT_NEAR(got.grid_origin[a], want.grid_origin[a], 1e-4f);
    }
  }
  // Two training cameras with corrections; a view a quarter of the way from the first.
  const VolumeShape shape = VolumeShape(2, 1, 1).WithPoses(2);
  std::vector<float> x(shape.ParamCount(), 0.f);
  std::vector<ViewFrustum> views(2);
  views[1].camera.world_from_cam[3] = 4.f;
  x[PoseParam(shape.PoseStart(), 0) + 2] = 0.04f;
  x[PoseParam(shape.PoseStart(), 1) + 2] = 0.08f;
  const PhotoCorrections e(shape, x, views, g);
  EXPECT_TRUE(e.has_poses());
  EXPECT_TRUE(e.transforms().empty());
  PinholeCamera<float> at{};
  at.world_from_cam[3] = 1.f;
  EXPECT_NEAR(e.PoseFor(at)[2], 0.75f * 0.04f + 0.25f * 0.08f, 1e-6f);
  EXPECT_FLOAT_EQ(e.PoseFor(views[1].camera)[2], 0.08f);
  EXPECT_FLOAT_EQ(PhotoCorrections().CameraFor(cam).world_from_cam[5], cam.world_from_cam[5]);
}

// The photos' exposures and pose corrections carry over from level to level; a level that stops
// refining poses keeps the exposures.
TEST(VolumeTest, ResampleCarriesExposuresAndPoses) {
  const VolumeShape from = VolumeShape(4, 2, 1, nullptr, 3).WithPoses(3);
  std::vector<float> x(from.ParamCount(), 0.5f);
  for (int64_t i = from.ExposureStart(); i < from.ParamCount(); ++i) x[i] = 0.001f * static_cast<float>(i % 97);
  const std::vector<float> same = Resample(from, x, from.Doubled());
  const VolumeShape to = from.Doubled();
  for (int64_t k = 0; k < from.ParamCount() - from.ExposureStart(); ++k) {
    EXPECT_EQ(same[to.ExposureStart() + k], x[from.ExposureStart() + k]) << k;
  }
  const VolumeShape unposed = to.WithPoses(0);
  const std::vector<float> kept = Resample(from, x, unposed);
  ASSERT_EQ(static_cast<int64_t>(kept.size()), unposed.ParamCount());
  for (int64_t k = 0; k < unposed.ParamCount() - unposed.ExposureStart(); ++k) {
    EXPECT_EQ(kept[unposed.ExposureStart() + k], x[from.ExposureStart() + k]) << k;
  }
}

}  // namespace
}  // namespace perf::recon
