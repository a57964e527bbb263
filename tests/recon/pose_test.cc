// The pose derivatives of pose.h against central differences of the ray math in double: every
// ray of small problems (dense and brick-sparse grids, spherical harmonics, rays entering and
// leaving the box through different faces, every shell) at random pose corrections.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "recon_cuda/core/pose.h"
#include "tests/recon/recon_test_util.h"

namespace perf::recon {
namespace {

using test::DoubleRay;
using test::DoubleView;
using test::TinyProblem;

struct Checked {
  int rays = 0, skipped = 0, nonzero = 0, shell_moves = 0;
};

// The residuals (H, L) of ray i at x.
void Residuals(const TinyProblem& p, const VolumeView<double>& vol, int64_t i, const Jitter& jit, double out[4],
               int* count) {
  const double target[3] = {p.rays.colours[3 * i], p.rays.colours[3 * i + 1], p.rays.colours[3 * i + 2]};
  const RayOutput<double> o = Forward(vol, DoubleRay(p, vol, i, jit), jit, target, 0.3, 0.0);
  for (int c = 0; c < 3; ++c) out[c] = o.h[c];
  out[3] = o.residual[3];
  *count = o.count;
}

// Ray i's pose row from pose.h at x (its photo's pose values at *pose).
PoseRow<double> AnalyticRow(const TinyProblem& p, const VolumeView<double>& vol, int64_t i, const Jitter& jit,
                            int64_t* pose, int* count) {
  const BoxRay<double> ray = DoubleRay(p, vol, i, jit);
  const double target[3] = {0, 0, 0};
  const RayOutput<double> fwd = Forward(vol, ray, jit, target, 0.3, 0.0);
  GeometryVisitor<double> visit(vol, ray, jit);
  Backward(vol, ray, jit, fwd, visit);
  *pose = PoseParamOfSlot(vol, p.rays.exposure_slot[p.rays.pixels[i].camera]);
  *count = fwd.count;
  return PoseRowOf(vol, vol.params + *pose, test::DoubleForward(p, i), ray, visit.grad);
}

// Compares every ray's PoseRowOf with central differences in the pose values; returns counts.
Checked CheckPoseRows(const TinyProblem& p, const std::vector<float>& xf, uint32_t seed, double tol) {
  std::vector<double> x(xf.begin(), xf.end());
  const VolumeView<double> vol = DoubleView(p, x);
  Checked checked;
  for (int64_t i = 0; i < p.rays.size(); ++i) {
    const Jitter jit{seed, static_cast<uint32_t>(i), true, true};
    int64_t pose;
    int count;
    const PoseRow<double> row = AnalyticRow(p, vol, i, jit, &pose, &count);
    EXPECT_GE(pose, 0);
    EXPECT_LE(pose + kPoseValues, static_cast<int64_t>(x.size()));
    if (pose < 0 || pose + kPoseValues > static_cast<int64_t>(x.size())) return checked;
    double numeric[4][kPoseValues] = {};
    double at[4];
    int n_at;
    Residuals(p, vol, i, jit, at, &n_at);
    bool same_samples = true, kink = false;
    for (int v = 0; v < kPoseValues; ++v) {
      if (v == 7) continue;
      const double saved = x[pose + v], h = 1e-6;
      double plus[4], minus[4];
      int n_plus, n_minus;
      x[pose + v] = saved + h;
      Residuals(p, vol, i, jit, plus, &n_plus);
      x[pose + v] = saved - h;
      Residuals(p, vol, i, jit, minus, &n_minus);
      x[pose + v] = saved;
      same_samples = same_samples && n_plus == count && n_minus == count;
      for (int r = 0; r < 4; ++r) {
        numeric[r][v] = (plus[r] - minus[r]) / (2 * h);
        // A kink within h (a sample crossing a clamped border or a brick's edge, the entry face
        // changing): the one-sided slopes differ by far more than their O(h) error (relative to
        // the slope: the focal length's are the largest).
        kink = kink || std::abs((plus[r] - at[r]) / h - (at[r] - minus[r]) / h) > 1e-3 * (1 + std::abs(numeric[r][v]));
      }
    }
    if (!same_samples || kink) {  // a jump or a kink: no derivative to compare with
      ++checked.skipped;
      continue;
    }
    ++checked.rays;
    for (int r = 0; r < 4; ++r) {
      for (int v = 0; v < kPoseValues; ++v) {
        EXPECT_NEAR(row.j[r][v], numeric[r][v], tol * (1 + std::abs(numeric[r][v])))
            << "ray " << i << " residual " << r << " pose value " << v;
        if (std::abs(numeric[r][v]) > 1e-3) ++checked.nonzero;
      }
    }
  }
  return checked;
}

TEST(PoseTest, RotationVectorAndLeftJacobian) {
  const Vec3<double> w{0.3, -0.2, 0.5};
  Mat3<double> r, jl;
  RotationOfVector(w, &r, &jl);
  // Orthonormal with w as its axis.
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double dot = 0;
      for (int k = 0; k < 3; ++k) dot += r.m[3 * k + i] * r.m[3 * k + j];
      EXPECT_NEAR(dot, i == j ? 1.0 : 0.0, 1e-12);
    }
  }
  const Vec3<double> axis = MulMat(r, w);
  EXPECT_NEAR(axis.x, w.x, 1e-12);
  EXPECT_NEAR(axis.y, w.y, 1e-12);
  EXPECT_NEAR(axis.z, w.z, 1e-12);
  // R(w + e) = exp([J_l e]x) R(w) to first order: compare the directions they give a vector.
  const Vec3<double> v{0.2, 0.9, -0.4};
  for (int a = 0; a < 3; ++a) {
    Vec3<double> e{0, 0, 0};
    e[a] = 1e-7;
    Mat3<double> r2, unused;
    RotationOfVector(w + e, &r2, &unused);
    const Vec3<double> moved = MulMat(r2, v) - MulMat(r, v);
    const Vec3<double> turn = MulMat(jl, e);
    const Vec3<double> predicted = Cross(turn, MulMat(r, v));
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(moved[k] / 1e-7, predicted[k] / 1e-7, 1e-6);
  }
}

TEST(PoseTest, DerivativesMatchCentralDifferencesOnADenseGrid) {
  TinyProblem p(11, 4, 3, 3, 7, 6);
  p.AddPoses(5);
  const Checked c = CheckPoseRows(p, p.x, 17, 2e-5);
  EXPECT_GT(c.rays, 100);
  EXPECT_LT(c.skipped, c.rays / 10);
  EXPECT_GT(c.nonzero, 4 * c.rays);  // most of the 6 x 4 entries take part
}

TEST(PoseTest, DerivativesMatchWithSphericalHarmonics) {
  TinyProblem p(12, 4, 3, 3, 7, 6);
  p.AddSh(2, 9);
  p.AddPoses(6, 0.05f, 0.05f);
  const Checked c = CheckPoseRows(p, p.x, 3, 2e-5);
  EXPECT_GT(c.rays, 100);
  EXPECT_LT(c.skipped, c.rays / 10);
}

// Brick edges: a 16^3 grid with some bricks stored; rays cross into and out of stored bricks.
TEST(PoseTest, DerivativesMatchOnABrickSparseGrid) {
  TinyProblem p(13, 16, 3, 3, 8, 7);
  std::vector<uint8_t> active(8, 0);
  active[0] = active[3] = active[5] = active[6] = 1;
  test::SparseVersion sparse(p, active);
  TinyProblem q = p;
  q.shape = sparse.level.shape;
  q.x = sparse.x;
  q.AddPoses(8);
  const Checked c = CheckPoseRows(q, q.x, 21, 5e-5);
  EXPECT_GT(c.rays, 100);
  EXPECT_LT(c.skipped, c.rays / 5);
}

// A wrong derivative is caught: the check fails when the centre columns are scaled by 1.01.
TEST(PoseTest, TheCheckSeesASmallError) {
  TinyProblem p(11, 4, 3, 2, 5, 4);
  p.AddPoses(5);
  std::vector<double> x(p.x.begin(), p.x.end());
  const VolumeView<double> vol = DoubleView(p, x);
  int differ = 0;
  for (int64_t i = 0; i < p.rays.size(); ++i) {
    const Jitter jit{4, static_cast<uint32_t>(i), true, true};
    int64_t pose;
    int n;
    const PoseRow<double> row = AnalyticRow(p, vol, i, jit, &pose, &n);
    double plus[4], minus[4];
    const double saved = x[pose + 4], h = 1e-6;
    x[pose + 4] = saved + h;
    Residuals(p, vol, i, jit, plus, &n);
    x[pose + 4] = saved - h;
    Residuals(p, vol, i, jit, minus, &n);
    x[pose + 4] = saved;
    const double numeric = (plus[0] - minus[0]) / (2 * h);
    if (std::abs(1.01 * row.j[0][4] - numeric) > 2e-5 * (1 + std::abs(numeric))) ++differ;
  }
  EXPECT_GT(differ, 5);
}

}  // namespace
}  // namespace perf::recon
