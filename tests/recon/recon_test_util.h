// A tiny reconstruction problem shared by the recon tests: a rotated, non-cubic box, a small
// grid, two shells, a few cameras around it and random parameters; plus a dense Jacobian built
// from the double-precision per-ray math, to check the float backends against.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <span>
#include <utility>
#include <vector>

#include "recon_cuda/core/pose.h"
#include "recon_cuda/core/ray_math.h"
#include "recon_cuda/data/brick_grid.h"
#include "recon_cuda/solve/backend.h"
#include "tests/recon/per_param_visitor.h"

namespace perf::recon::test {

inline Vec3<float> Cross(Vec3<float> a, Vec3<float> b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

// A camera at `pos` looking at `target`, y roughly along -up (image y down).
inline PinholeCamera<float> LookAt(Vec3<float> pos, Vec3<float> target, float f, float cx, float cy,
                                   Vec3<float> up = {0, 0, 1}) {
  const Vec3<float> z = Normalized(target - pos);
  Vec3<float> x = Cross(z, up);
  if (Dot(x, x) < 1e-8f) x = Cross(z, Vec3<float>{0, 1, 0});
  x = Normalized(x);
  const Vec3<float> y = Cross(z, x);
  return {f, f, cx, cy, {x.x, y.x, z.x, pos.x, x.y, y.y, z.y, pos.y, x.z, y.z, z.z, pos.z}};
}

struct TinyProblem {
  VolumeShape shape;
  VolumeGeometry geometry;
  RaySet rays;
  std::vector<float> x;

  explicit TinyProblem(uint32_t seed, int n = 4, int m = 2, int cameras = 3, int width = 6, int height = 5) {
    std::mt19937 rng(seed);
    shape = {n, m, 2};
    const float c = 0.6f, s = 0.8f;  // rotation about z by ~37 degrees
    geometry.box = {{0.2f, -0.1f, 0.05f}, {{c, -s, 0, s, c, 0, 0, 0, 1}}, {2.0f, 1.6f, 1.4f}};
    geometry.shell_center = {0.1f, 0.0f, -0.1f};
    geometry.shell_radii = {2.5f, 5.0f};
    std::uniform_real_distribution<float> u(0.f, 1.f), col(0.1f, 0.9f), sig(0.2f, 2.5f), op(0.2f, 0.8f);
    for (int k = 0; k < cameras; ++k) {
      const float a = 6.2831853f * k / cameras + 0.3f;
      const Vec3<float> pos{3.0f * std::cos(a), 3.0f * std::sin(a), 0.8f * (u(rng) - 0.5f)};
      rays.cameras.push_back(LookAt(pos, geometry.box.center, 1.2f * width, width / 2.0f, height / 2.0f));
      for (int y = 0; y < height; ++y) {
        for (int px = 0; px < width; ++px) {
          rays.pixels.push_back({static_cast<uint32_t>(k), static_cast<uint16_t>(px), static_cast<uint16_t>(y)});
          for (int ch = 0; ch < 3; ++ch) rays.colours.push_back(u(rng));
        }
      }
    }
    x.resize(shape.ParamCount());
    for (int64_t i = 0; i < shape.ParamCount(); ++i) {
      switch (KindOf(shape, i)) {
        case ParamKind::kGridDensity: x[i] = sig(rng); break;
        case ParamKind::kShellOpacity: x[i] = op(rng); break;
        default: x[i] = col(rng); break;
      }
    }
  }

  // Spherical harmonics of `degree` on every stored cell (VolumeShape::sh_degree), random in
  // [-0.3, 0.3] (padding zeros). Before AddExposures (the exposures follow them).
  void AddSh(int degree, uint32_t seed) {
    ASSERT_EQ(shape.exposures, 0);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> coef(-0.3f, 0.3f);
    shape = shape.WithShDegree(degree);
    const int stride = ShStride(degree);
    for (int64_t c = 0; c < shape.StoredCells(); ++c) {
      for (int j = 0; j < stride; ++j) x.push_back(j < 3 * ShBands(degree) ? coef(rng) : 0.f);
    }
    EXPECT_EQ(static_cast<int64_t>(x.size()), shape.ParamCount());
  }

  // Solves every camera's exposure (VolumeShape::exposures): random gains 1 + gamma and offsets,
  // and camera k in slot (k + 1) % cameras (so that slots and cameras differ).
  void AddExposures(uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> gamma(-0.3f, 0.3f), offset(-0.1f, 0.1f);
    const int cameras = static_cast<int>(rays.cameras.size());
    shape = shape.WithExposures(cameras);
    rays.exposure_slot.clear();
    for (int k = 0; k < cameras; ++k) rays.exposure_slot.push_back((k + 1) % cameras);
    for (int k = 0; k < cameras; ++k) {
      for (int v = 0; v < kExposureValues; ++v) x.push_back(v % 4 == 3 ? 0.f : v < 4 ? gamma(rng) : offset(rng));
    }
    EXPECT_EQ(static_cast<int64_t>(x.size()), shape.ParamCount());
  }

  // Refines every camera's pose (VolumeShape::poses) from random corrections of up to `rotation`
  // rad and `centre` box units per axis; camera k in slot (k + 1) % cameras as for exposures
  // (the slots are shared: RaySet::exposure_slot). After AddExposures when both are wanted.
  // Pose corrections up to `rotation` rad, `centre` box units and a focal log scale up to `focal`.
  void AddPoses(uint32_t seed, float rotation = 0.02f, float centre = 0.02f, float focal = 0.02f) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> w(-rotation, rotation), c(-centre, centre), f(-focal, focal);
    const int cameras = static_cast<int>(rays.cameras.size());
    shape = shape.WithPoses(cameras);
    rays.exposure_slot.clear();
    for (int k = 0; k < cameras; ++k) rays.exposure_slot.push_back((k + 1) % cameras);
    for (int k = 0; k < cameras; ++k) {
      for (int v = 0; v < kPoseValues; ++v) x.push_back(v == 7 ? 0.f : v == 3 ? f(rng) : v < 3 ? w(rng) : c(rng));
    }
    EXPECT_EQ(static_cast<int64_t>(x.size()), shape.ParamCount());
  }

  // Pixel jitter on by default so that the tests cover the jittered ray as well. lambda weighs
  // the fourth residual of either kind (the paper's term, or the alpha one where rays carry alpha).
  LevelProblem Level(float lambda = 0.1f, bool pixel_jitter = true) const {
    return {shape, geometry, &rays, {lambda, 0.f, true, pixel_jitter, true, lambda}};
  }
};

// A direction for J^T J p checks: standard normal entries, except the padding zeros that never
// move (the spherical harmonics' stride beyond their bands, the fourth value of each exposure
// group, the last of each pose group), which stay 0.
inline std::vector<float> RandomDirection(const VolumeShape& shape, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal;
  std::vector<float> p(shape.ParamCount());
  for (float& v : p) v = normal(rng);
  if (shape.sh_degree > 0) {
    const int stride = ShStride(shape.sh_degree);
    for (int64_t c = 0; c < shape.StoredCells(); ++c)
      for (int k = 3 * ShBands(shape.sh_degree); k < stride; ++k) p[shape.ShStart() + stride * c + k] = 0;
  }
  for (int64_t i = shape.ExposureStart(); i < shape.PoseStart(); ++i) {
    if ((i - shape.ExposureStart()) % 4 == 3) p[i] = 0;
  }
  for (int64_t i = shape.PoseStart(); i < shape.ParamCount(); ++i) {
    if ((i - shape.PoseStart()) % kPoseValues == 7) p[i] = 0;
  }
  return p;
}

// The problem's volume as the double-precision ray math reads it (params: x, which must outlive it).
inline VolumeView<double> DoubleView(const TinyProblem& p, const std::vector<double>& x) {
  VolumeView<double> vol{};
  vol.params = x.data();
  vol.n = p.shape.n;
  vol.m = p.shape.m;
  vol.num_shells = p.shape.num_shells;
  vol.sh_degree = p.shape.sh_degree;
  vol.exposures = p.shape.exposures;
  vol.poses = p.shape.poses;
  vol.size = {p.geometry.box.size.x, p.geometry.box.size.y, p.geometry.box.size.z};
  vol.shell_center = {p.geometry.shell_center.x, p.geometry.shell_center.y, p.geometry.shell_center.z};
  for (int k = 0; k < p.shape.num_shells; ++k) vol.shell_radii[k] = p.geometry.shell_radii[k];
  if (p.shape.bricks) {  // a brick-sparse x
    vol.brick_slot = p.shape.bricks->slot.data();
    vol.skip_blocks = p.shape.bricks->skip_blocks.data();
    vol.active_bricks = p.shape.bricks->ActiveBricks();
  }
  EXPECT_EQ(static_cast<int64_t>(x.size()), p.shape.ParamCount());
  return vol;
}

inline BoxFrame<double> DoubleBox(const TinyProblem& p) {
  BoxFrame<double> box;
  box.center = {p.geometry.box.center.x, p.geometry.box.center.y, p.geometry.box.center.z};
  box.size = {p.geometry.box.size.x, p.geometry.box.size.y, p.geometry.box.size.z};
  for (int i = 0; i < 9; ++i) box.world_from_box.m[i] = p.geometry.box.world_from_box.m[i];
  return box;
}

// The optical axis of ray i's camera in the box frame (pose.h BoxForward), in double.
inline Vec3<double> DoubleForward(const TinyProblem& p, int64_t i) {
  const PinholeCamera<float>& cf = p.rays.cameras[p.rays.pixels[i].camera];
  PinholeCamera<double> cam{cf.fx, cf.fy, cf.cx, cf.cy, {}};
  for (int k = 0; k < 12; ++k) cam.world_from_cam[k] = cf.world_from_cam[k];
  return BoxForward(cam, DoubleBox(p));
}

// Ray i of the problem at x, as the backends march it: through its pixel (jittered for `jit`),
// then moved by its photo's pose correction when the problem refines poses.
inline BoxRay<double> DoubleRay(const TinyProblem& p, const VolumeView<double>& vol, int64_t i, const Jitter& jit) {
  const RayPixel& px = p.rays.pixels[i];
  const PinholeCamera<float>& cf = p.rays.cameras[px.camera];
  PinholeCamera<double> cam{cf.fx, cf.fy, cf.cx, cf.cy, {}};
  for (int k = 0; k < 12; ++k) cam.world_from_cam[k] = cf.world_from_cam[k];
  BoxRay<double> ray = PixelBoxRay(cam, DoubleBox(p), vol.n, px.x, px.y, jit);
  const int64_t pose = p.shape.poses > 0 ? PoseParamOfSlot(vol, p.rays.exposure_slot[px.camera]) : -1;
  if (pose >= 0) ApplyPose(vol, vol.params + pose, DoubleForward(p, i), &ray);
  return ray;
}

// The dense Jacobian [4 rays, params] and residuals of every ray, in double, from the per-ray
// math at x (as floats widened to double) with the rays' jitter for `seed`.
struct DenseJacobian {
  std::vector<std::vector<double>> rows;  // [4 * rays][params]
  std::vector<double> residuals;          // [4 * rays]
  // Every single visit's squared partials: what diag(J^T J) would be without merging visits.
  std::vector<std::pair<int64_t, double>> naive_diag_terms;

  // robust: the Cauchy scale c of the colour residuals (ResidualSettings::robust_scale; 0: least
  // squares); with it the rows and residuals are those of the reweighted system (jacobian.h
  // RobustRowScale) and Cost() is the robust cost.
  template <class S>
  DenseJacobian(const TinyProblem& p, const std::vector<S>& xs, uint32_t seed, double lambda, bool jitter = true,
                bool pixel_jitter = true, double robust = 0) {
    std::vector<double> x(xs.begin(), xs.end());
    const VolumeView<double> vol = DoubleView(p, x);
    for (int64_t i = 0; i < p.rays.size(); ++i) {
      const RayPixel& px = p.rays.pixels[i];
      const Jitter jit{seed, static_cast<uint32_t>(i), jitter, pixel_jitter};
      const BoxRay<double> ray = DoubleRay(p, vol, i, jit);
      const double target[3] = {p.rays.colours[3 * i], p.rays.colours[3 * i + 1], p.rays.colours[3 * i + 2]};
      // The rays' alpha when they carry one (the backends' default use_alpha), else the paper's term.
      const double alpha = p.rays.alphas.empty() ? -1.0 : p.rays.alphas[i];
      const RayOutput<double> out = Forward(vol, ray, jit, target, lambda, 0.0, nullptr, alpha);
      // With exposures, the photo shows (1 + gamma_c) H_c + b_c (ray_types.h ExposureParam):
      // written out here from H, the volume's partials of H times the gain, and H and 1 for the
      // exposure's own columns.
      const int64_t e = p.shape.exposures > 0
                            ? p.shape.ExposureStart() + kExposureValues * int64_t{p.rays.exposure_slot[px.camera]}
                            : -1;
      double gain[3] = {1, 1, 1}, residual[4] = {out.residual[0], out.residual[1], out.residual[2], out.residual[3]};
      if (e >= 0) {
        for (int c = 0; c < 3; ++c) {
          gain[c] = 1 + x[e + c];
          residual[c] = gain[c] * out.h[c] + x[e + 4 + c] - target[c];
        }
      }
      std::vector<std::vector<double>> j(4, std::vector<double>(x.size(), 0.0));
      auto f = [&](int64_t idx, double a, double b, double c, double d) {
        j[0][idx] += gain[0] * a;
        j[1][idx] += gain[1] * b;
        j[2][idx] += gain[2] * c;
        j[3][idx] += d;
      };
      auto g = [&](int64_t idx, double a, double b, double c, double d) {
        f(idx, a, b, c, d);
        a *= gain[0], b *= gain[1], c *= gain[2];
        naive_diag_terms.push_back({idx, a * a + b * b + c * c + d * d});
      };
      BackwardPerParam(vol, ray, jit, out, g);
      if (e >= 0) {
        for (int c = 0; c < 3; ++c) {
          j[c][e + c] = out.h[c];
          j[c][e + 4 + c] = 1;
        }
      }
      // The pose's columns by central differences of the residuals (pose.h derives them).
      const int64_t pose = p.shape.poses > 0 ? PoseParamOfSlot(vol, p.rays.exposure_slot[px.camera]) : -1;
      for (int v = 0; pose >= 0 && v < kPoseValues; ++v) {
        if (v == 7) continue;
        const double saved = x[pose + v], h = 1e-6;
        double r_at[2][4];
        for (int side = 0; side < 2; ++side) {
          x[pose + v] = saved + (side == 0 ? h : -h);
          const RayOutput<double> o = Forward(vol, DoubleRay(p, vol, i, jit), jit, target, lambda, 0.0, nullptr, alpha);
          for (int c = 0; c < 3; ++c) r_at[side][c] = gain[c] * o.h[c];
          r_at[side][3] = o.residual[3];
        }
        x[pose + v] = saved;
        for (int r = 0; r < 4; ++r) j[r][pose + v] = (r_at[0][r] - r_at[1][r]) / (2 * h);
      }
      // The robust loss: the colour rows and residuals times s = 1 / sqrt(1 + q / c^2), and the
      // ray's colour cost 0.5 c^2 log(1 + q / c^2) (q = |r_colour|^2) instead of 0.5 q.
      const double q = residual[0] * residual[0] + residual[1] * residual[1] + residual[2] * residual[2];
      const double s = robust > 0 ? 1 / std::sqrt(1 + q / (robust * robust)) : 1.0;
      row_scales.push_back(s);
      colour_cost += robust > 0 ? 0.5 * robust * robust * std::log1p(q / (robust * robust)) : 0.5 * q;
      opacity_cost += 0.5 * residual[3] * residual[3];
      for (int c = 0; c < 3; ++c) {
        residual[c] *= s;
        for (double& v : j[c]) v *= s;
      }
      for (int r = 0; r < 4; ++r) {
        rows.push_back(std::move(j[r]));
        residuals.push_back(residual[r]);
      }
    }
  }

  std::vector<double> Jtr() const { return Jtu(residuals); }
  std::vector<double> Jtu(const std::vector<double>& u) const {
    std::vector<double> g(rows[0].size(), 0.0);
    for (size_t r = 0; r < rows.size(); ++r)
      for (size_t i = 0; i < g.size(); ++i) g[i] += rows[r][i] * u[r];
    return g;
  }
  std::vector<double> Jp(const std::vector<double>& p) const {
    std::vector<double> u(rows.size(), 0.0);
    for (size_t r = 0; r < rows.size(); ++r)
      for (size_t i = 0; i < p.size(); ++i) u[r] += rows[r][i] * p[i];
    return u;
  }
  std::vector<double> Diag() const {
    std::vector<double> d(rows[0].size(), 0.0);
    for (const auto& row : rows)
      for (size_t i = 0; i < d.size(); ++i) d[i] += row[i] * row[i];
    return d;
  }
  double Cost() const { return colour_cost + opacity_cost; }
  double colour_cost = 0, opacity_cost = 0;
  std::vector<double> row_scales;  // [rays] the robust loss's (1 without)
};

// Every entry of `got` within scale_tol * max|want| + rel_tol * |want_i| of `want`, and more than
// `exercised` of the entries (a share) clearly non-zero (so the comparison exercised something).
template <class G, class W>
void ExpectAllClose(const std::vector<G>& got, const std::vector<W>& want, double scale_tol, double rel_tol,
                    const char* what, double exercised = 0.1) {
  ASSERT_EQ(got.size(), want.size());
  double scale = 0;
  for (W v : want) scale = std::max(scale, std::abs(static_cast<double>(v)));
  ASSERT_GT(scale, 0) << what;
  int nonzero = 0;
  for (size_t i = 0; i < want.size(); ++i) {
    const double w = want[i];
    ASSERT_NEAR(got[i], w, scale_tol * scale + rel_tol * std::abs(w)) << what << " entry " << i;
    if (std::abs(w) > 1e-3 * scale) ++nonzero;
  }
  EXPECT_GT(nonzero, static_cast<int>(exercised * static_cast<double>(want.size())))
      << what << ": too few entries exercised";
}

// A TinyProblem (n a multiple of 8) with only some bricks stored: the sparse level and its x, and
// the dense x with every cell of the other bricks zeroed (all four channels), which the sparse
// level must reproduce (ray_math.h TakeSample).
struct SparseVersion {
  LevelProblem level;
  std::vector<float> x, dense_x;

  SparseVersion(const TinyProblem& p, const std::vector<uint8_t>& active) {
    auto bricks = std::make_shared<const BrickGrid>(MakeBrickGrid(p.shape.n, active));
    level = p.Level();
    level.shape = p.shape.WithBricks(bricks);
    const int64_t grid = p.shape.GridParamCount();
    const std::span<const float> dense_grid(p.x.data(), static_cast<size_t>(grid));
    x = PackGrid<float>(*bricks, dense_grid);
    dense_x = UnpackGrid<float>(*bricks, x);
    x.insert(x.end(), p.x.begin() + grid, p.x.end());
    dense_x.insert(dense_x.end(), p.x.begin() + grid, p.x.end());
  }
  // A dense-layout vector's entries at the stored cells and the shells (the sparse layout).
  std::vector<float> Stored(const std::vector<float>& dense) const {
    const int64_t grid = GridParamCount(level.shape.n);
    std::vector<float> out = PackGrid<float>(*level.shape.bricks, std::span<const float>(dense.data(), grid));
    out.insert(out.end(), dense.begin() + grid, dense.end());
    return out;
  }
  // A sparse-layout vector in the dense layout (0 in the other bricks).
  std::vector<float> Dense(const std::vector<float>& sparse) const {
    const int64_t grid = level.shape.GridParamCount();
    std::vector<float> out = UnpackGrid<float>(*level.shape.bricks, std::span<const float>(sparse.data(), grid));
    out.insert(out.end(), sparse.begin() + grid, sparse.end());
    return out;
  }
};

}  // namespace perf::recon::test
