// Per-ray math (recon_cuda/core/ray_math.h) in double: every partial of the backward sweep against
// central finite differences of the forward, plus the geometry pieces it is built from.
#include "recon_cuda/core/ray_math.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "tests/recon/per_param_visitor.h"
#include "tests/recon/random_rays.h"

namespace perf::recon {
namespace {

using V3 = Vec3<double>;

Mat3<double> AxisAngle(V3 axis, double angle) {
  const V3 a = Normalized(axis);
  const double c = std::cos(angle), s = std::sin(angle), t = 1 - c;
  return {{t * a.x * a.x + c, t * a.x * a.y - s * a.z, t * a.x * a.z + s * a.y,
           t * a.x * a.y + s * a.z, t * a.y * a.y + c, t * a.y * a.z - s * a.x,
           t * a.x * a.z - s * a.y, t * a.y * a.z + s * a.x, t * a.z * a.z + c}};
}


// A rotated, non-cubic box, N = 4 grid, K = 2 shells of M = 4, random positive parameters.
struct TestScene {
  BoxFrame<double> box;
  std::vector<double> x;
  VolumeView<double> vol;

  explicit TestScene(std::mt19937& rng, int n = 4, int m = 4) {
    box.center = {0.3, -0.2, 0.1};
    box.world_from_box = AxisAngle({0.3, 1.0, -0.4}, 0.7);
    box.size = {2.0, 1.5, 1.2};
    x.resize(ParamCount(n, m, 2));
    std::uniform_real_distribution<double> colour(0.1, 0.9), sigma(0.3, 3.0), opacity(0.2, 0.8);
    for (int64_t c = 0; c < int64_t{n} * n * n; ++c) {
      for (int ch = 0; ch < 3; ++ch) x[GridParam(c, ch)] = colour(rng);
      x[GridParam(c, 3)] = sigma(rng);
    }
    for (int64_t i = GridParamCount(n); i < static_cast<int64_t>(x.size()); i += 4) {
      for (int ch = 0; ch < 3; ++ch) x[i + ch] = colour(rng);
      x[i + 3] = opacity(rng);
    }
    vol.params = x.data();
    vol.n = n;
    vol.size = box.size;
    vol.num_shells = 2;
    vol.m = m;
    vol.shell_center = MulMatTransposed(box.world_from_box, V3{0.1, 0.0, -0.1});
    vol.shell_radii[0] = 3.0;
    vol.shell_radii[1] = 6.0;
  }
};

// A camera 2.5 from the box centre looking at it, and a random pixel of a 64 x 48 image.
BoxRay<double> RandomCameraRay(const TestScene& s, std::mt19937& rng, double distance = 2.5) {
  return test::RandomCameraRay(s.box, s.vol.n, rng, distance);
}

struct DenseRow {
  std::vector<double> j[4];  // dr_c / dx for the 4 residuals
  explicit DenseRow(size_t n) {
    for (auto& v : j) v.assign(n, 0.0);
  }
  void operator()(int64_t i, double dr, double dg, double db, double dl) {
    j[0][i] += dr;
    j[1][i] += dg;
    j[2][i] += db;
    j[3][i] += dl;
  }
};

// alpha < 0: the paper's auxiliary residual; alpha >= 0: the alpha residual (AuxResidual).
class EveryPartial : public ::testing::TestWithParam<double> {};

TEST_P(EveryPartial, MatchesCentralDifferences) {
  const double alpha = GetParam();
  std::mt19937 rng(7);
  TestScene s(rng);
  const double target[3] = {0.2, 0.5, 0.7};
  const double lambda = 0.1, h = 1e-5;
  std::vector<BoxRay<double>> rays;
  for (int i = 0; i < 8; ++i) rays.push_back(RandomCameraRay(s, rng));
  rays.push_back(RandomCameraRay(s, rng, 0.2));                          // starts inside the box
  rays.push_back(ToBoxRay(s.box, s.vol.n, s.box.center + V3{0, 0, 2.5}, V3{0, 0, 1}));  // misses the box
  int nonzero[6] = {};  // grid colour, grid sigma, shell colour, shell opacity, dL/dsigma, dH/d(box) on miss
  for (size_t r = 0; r < rays.size(); ++r) {
    const Jitter jit{1234u, static_cast<uint32_t>(r), true, true};
    const RayOutput<double> out = Forward(s.vol, rays[r], jit, target, lambda, 0.0, nullptr, alpha);
    DenseRow row(s.x.size());
    BackwardPerParam(s.vol, rays[r], jit, out, row);
    for (size_t p = 0; p < s.x.size(); ++p) {
      const double keep = s.x[p];
      s.x[p] = keep + h;
      const RayOutput<double> plus = Forward(s.vol, rays[r], jit, target, lambda, 0.0, nullptr, alpha);
      s.x[p] = keep - h;
      const RayOutput<double> minus = Forward(s.vol, rays[r], jit, target, lambda, 0.0, nullptr, alpha);
      s.x[p] = keep;
      const bool grid = static_cast<int64_t>(p) < GridParamCount(s.vol.n);
      for (int c = 0; c < 4; ++c) {
        const double fd = (plus.residual[c] - minus.residual[c]) / (2 * h);
        ASSERT_NEAR(row.j[c][p], fd, 1e-7 + 1e-6 * std::abs(fd)) << "ray " << r << " param " << p << " res " << c;
        if (std::abs(fd) > 1e-4) {
          const int ch = static_cast<int>(p % 4);
          if (c == 3) ++nonzero[4];
          else if (grid) ++nonzero[ch == 3 ? 1 : 0];
          else ++nonzero[ch == 3 ? 3 : 2];
          if (r + 1 == rays.size() && grid) ++nonzero[5];
        }
      }
    }
  }
  EXPECT_GT(nonzero[0], 50);
  EXPECT_GT(nonzero[1], 50);
  EXPECT_GT(nonzero[2], 20);
  EXPECT_GT(nonzero[3], 10);
  EXPECT_GT(nonzero[4], 20);
  EXPECT_EQ(nonzero[5], 0);
}
INSTANTIATE_TEST_SUITE_P(OpacityResidual, EveryPartial, ::testing::Values(-1.0, 0.0, 0.35, 1.0));

TEST(RayMathTest, AlphaResidualIsTheOpacityError) {
  double l, dl;
  AuxResidual(0.25, 0.1, 0.6, &l, &dl);  // box opacity 0.75, alpha 0.6
  EXPECT_NEAR(l, 0.1 * 0.15, 1e-15);
  EXPECT_EQ(dl, -0.1);
  AuxResidual(0.25, 0.1, -1.0, &l, &dl);  // no alpha: lambda (1 - 4 (T - 0.5)^2)
  EXPECT_NEAR(l, 0.1 * 0.75, 1e-15);
  EXPECT_NEAR(dl, 0.2, 1e-15);
}

TEST(RayMathTest, SlabTestCases) {
  const double n = 4;
  SlabHit<double> s = SlabTest(V3{-1, 2, 2}, V3{1, 0, 0}, n);  // axis-parallel through
  EXPECT_TRUE(s.hit);
  EXPECT_DOUBLE_EQ(s.t_min, 1);
  EXPECT_DOUBLE_EQ(s.t_max, 5);
  s = SlabTest(V3{2, 2, -3}, V3{0, 0, -2}, n);  // axis-parallel, pointing away
  EXPECT_FALSE(s.hit);
  s = SlabTest(V3{2, 2, 6}, V3{0, 0, -2}, n);  // axis-parallel, backwards, |d| != 1
  EXPECT_TRUE(s.hit);
  EXPECT_DOUBLE_EQ(s.t_min, 1);
  EXPECT_DOUBLE_EQ(s.t_max, 3);
  EXPECT_FALSE(SlabTest(V3{-1, 5, 2}, V3{1, 0, 0}, n).hit);   // parallel, outside the y slab
  EXPECT_FALSE(SlabTest(V3{-1, -1, 2}, V3{1, -1, 0}, n).hit); // diagonal, misses
  s = SlabTest(V3{2, 1, 3}, V3{1, 0, 0}, n);                  // starts inside
  EXPECT_TRUE(s.hit);
  EXPECT_DOUBLE_EQ(s.t_min, 0);
  EXPECT_DOUBLE_EQ(s.t_max, 2);
  s = SlabTest(V3{-1, -1, -1}, V3{1, 1, 1}, n);  // corner to corner
  EXPECT_TRUE(s.hit);
  EXPECT_DOUBLE_EQ(s.t_min, 1);
  EXPECT_DOUBLE_EQ(s.t_max, 5);
  EXPECT_FALSE(SlabTest(V3{5, 5, 5}, V3{1, 1, 1}, n).hit);  // behind the origin
}

TEST(RayMathTest, PixelRayAndBoxFrame) {
  PinholeCamera<double> cam{100, 80, 31.5, 23.5, {1, 0, 0, 1, 0, 1, 0, 2, 0, 0, 1, 3}};
  V3 o, d;
  PixelRay(cam, 31, 23, 0.5, 0.5, &o, &d);  // the centre of pixel (31, 23) is (31.5, 23.5)
  EXPECT_DOUBLE_EQ(o.x, 1);
  EXPECT_DOUBLE_EQ(o.z, 3);
  EXPECT_NEAR(d.x, 0, 1e-15);
  EXPECT_NEAR(d.y, 0, 1e-15);
  EXPECT_NEAR(d.z, 1, 1e-15);
  PixelRay(cam, 0, 0, 0.0, 0.0, &o, &d);  // upper-left corner: x left, y up
  EXPECT_NEAR(d.x / d.z, -31.5 / 100, 1e-15);
  EXPECT_NEAR(d.y / d.z, -23.5 / 80, 1e-15);

  std::mt19937 rng(3);
  TestScene s(rng);
  const V3 wo{0.4, 2.0, -1.0}, wd = Normalized(V3{-0.2, -1.0, 0.6});
  const BoxRay<double> r = ToBoxRay(s.box, 4, wo, wd);
  for (double t : {0.0, 0.7, 2.5}) {
    // grid = (R^T (p - center) + size / 2) * n / size: the box's min corner is grid 0.
    const V3 q = MulMatTransposed(s.box.world_from_box, wo + wd * t - s.box.center);
    const V3 g = r.GridPoint(t);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(g[a], (q[a] + s.box.size[a] / 2) * 4 / s.box.size[a], 1e-12);
  }
  const V3 corner = s.box.center + MulMat(s.box.world_from_box, s.box.size * -0.5);
  const BoxRay<double> rc = ToBoxRay(s.box, 4, corner, V3{1, 0, 0});
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(rc.grid_origin[a], 0, 1e-12);
}

TEST(RayMathTest, MarchCoversTheBoxWithJitteredSamples) {
  std::mt19937 rng(5);
  TestScene s(rng);
  for (int i = 0; i < 20; ++i) {
    const BoxRay<double> ray = RandomCameraRay(s, rng);
    const March<double> m = MakeMarch(s.vol, ray);
    if (!m.hit) continue;
    EXPECT_DOUBLE_EQ(m.delta, 1.2 / 4);  // shortest cell side, world units
    double total = 0;
    for (int k = 0; k < m.count; ++k) {
      const MarchStep<double> st = StepAt(m, k, Jitter{9, static_cast<uint32_t>(i), true, true});
      const double start = m.t_min + k * m.delta;
      EXPECT_GE(st.t, start);
      EXPECT_LE(st.t, start + st.delta);
      EXPECT_LE(st.t, m.t_max);
      total += st.delta;
    }
    EXPECT_NEAR(total, m.t_max - m.t_min, 1e-12);
  }
}

TEST(RayMathTest, TrilinearReproducesALinearField) {
  const int n = 4;
  std::vector<double> grid(GridParamCount(n));
  auto field = [](V3 p, int ch) { return 0.3 + (ch + 1) * 0.1 * p.x - 0.2 * p.y + 0.05 * ch * p.z; };
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (int ch = 0; ch < 4; ++ch)
          grid[GridParam(GridCell(n, i, j, k), ch)] = field(V3{i + 0.5, j + 0.5, k + 0.5}, ch);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.5, n - 0.5);
  for (int t = 0; t < 200; ++t) {
    const V3 p{u(rng), u(rng), u(rng)};
    const GridSample<double> gs = TrilinearWeights(n, nullptr, p);
    double v[4], wsum = 0;
    GatherGrid(grid.data(), gs, v);
    for (double w : gs.w) wsum += w;
    EXPECT_NEAR(wsum, 1, 1e-14);
    for (int ch = 0; ch < 4; ++ch) EXPECT_NEAR(v[ch], field(p, ch), 1e-13);
  }
  double a[4], b[4];  // clamped: outside the centres' hull the border value holds
  GatherGrid(grid.data(), TrilinearWeights(n, nullptr, V3{-1, 2, 4}), a);
  GatherGrid(grid.data(), TrilinearWeights(n, nullptr, V3{0.5, 2, 3.5}), b);
  for (int ch = 0; ch < 4; ++ch) EXPECT_NEAR(a[ch], b[ch], 1e-14);
}

// A brick-sparse grid's cells: the one-brick shortcut of TrilinearWeights gives each corner the
// cell SparseCell gives it, at brick edges, the box's border and next to inactive bricks.
TEST(RayMathTest, SparseTrilinearCellsMatchEachCornersLookup) {
  const int n = 32, nb = n / kBrickSide;
  std::mt19937 rng(17);
  std::vector<int32_t> slot(BrickCount(n));
  int32_t next = 0;
  for (auto& s : slot) s = rng() % 3 == 0 ? kInactiveBrick : next++;
  std::uniform_real_distribution<double> u(-0.5, n + 0.5);
  std::uniform_int_distribution<int> edge(1, nb - 1);
  int one_brick = 0, spanning = 0, inactive = 0;
  for (int t = 0; t < 20000; ++t) {
    V3 p{u(rng), u(rng), u(rng)};
    if (t % 2) p[t % 3] = edge(rng) * kBrickSide + (u(rng) - n / 2.0) / n;  // within half a cell of a brick edge
    const GridSample<double> gs = TrilinearWeights(n, slot.data(), p);
    int lo[3], hi[3];
    double f[3];
    for (int a = 0; a < 3; ++a) LinearCoord(p[a], n, &lo[a], &hi[a], &f[a]);
    for (int c = 0; c < 8; ++c) {
      const int64_t want =
          SparseCell(slot.data(), nb, c & 1 ? hi[0] : lo[0], c & 2 ? hi[1] : lo[1], c & 4 ? hi[2] : lo[2]);
      ASSERT_EQ(gs.cell[c], want) << "corner " << c << " of (" << p.x << ", " << p.y << ", " << p.z << ")";
      EXPECT_EQ(gs.w[c], (c & 1 ? f[0] : 1 - f[0]) * (c & 2 ? f[1] : 1 - f[1]) * (c & 4 ? f[2] : 1 - f[2]));
    }
    const bool same = lo[0] / 8 == hi[0] / 8 && lo[1] / 8 == hi[1] / 8 && lo[2] / 8 == hi[2] / 8;
    (same ? one_brick : spanning) += 1;
    inactive += gs.cell[0] < 0;
  }
  EXPECT_GT(one_brick, 5000);  // both paths and inactive bricks are exercised
  EXPECT_GT(spanning, 5000);
  EXPECT_GT(inactive, 2000);
}

TEST(RayMathTest, CubeMapRoundTripAndContinuity) {
  std::mt19937 rng(13);
  std::normal_distribution<double> g;
  for (int t = 0; t < 500; ++t) {
    const V3 d = Normalized(V3{g(rng), g(rng), g(rng)});
    const CubeCoord<double> c = DirectionToCube(d);
    ASSERT_GE(c.u, 0);
    ASSERT_LE(c.u, 1);
    ASSERT_GE(c.v, 0);
    ASSERT_LE(c.v, 1);
    const V3 back = Normalized(CubeToDirection(c));
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(back[a], d[a], 1e-12);
  }
  // Texels hold a smooth function of their centre's direction: lookups are continuous inside a
  // face and, across face edges (faces are clamped, not stitched), jump by < one texel's change.
  const int n = 1, m = 16;
  std::vector<double> x(ParamCount(n, m, 1));
  auto f = [](V3 d) { return 0.5 + 0.4 * d.x - 0.3 * d.y + 0.2 * d.z; };
  for (int face = 0; face < 6; ++face)
    for (int v = 0; v < m; ++v)
      for (int u = 0; u < m; ++u)
        x[ShellParam(n, m, 0, face, u, v, 0)] =
            f(Normalized(CubeToDirection(CubeCoord<double>{face, (u + 0.5) / m, (v + 0.5) / m})));
  auto lookup = [&](V3 d) {
    double out[4];
    GatherTexels(x.data(), TexelWeights(GridParamCount(n), m, 0, DirectionToCube(d)), out);
    return out[0];
  };
  double worst_edge = 0;
  for (int t = 0; t < 2000; ++t) {
    const V3 d = Normalized(V3{g(rng), g(rng), g(rng)});
    const V3 e = Normalized(d + V3{g(rng), g(rng), g(rng)} * 1e-7);
    const double jump = std::abs(lookup(d) - lookup(e));
    if (DirectionToCube(d).face == DirectionToCube(e).face) {
      EXPECT_LT(jump, 1e-5);
    } else {
      worst_edge = std::max(worst_edge, jump);
    }
    EXPECT_NEAR(lookup(d), f(d), 0.05);  // bilinear approximates the field
  }
  EXPECT_LT(worst_edge, 0.1);
  // Across each of the 12 edges explicitly: the point on +x just before/after the +x/+y edge.
  EXPECT_LT(std::abs(lookup(V3{1, 1 - 1e-9, 0.3}) - lookup(V3{1 - 1e-9, 1, 0.3})), 0.1);
}

TEST(RayMathTest, HashIsInUnitIntervalAndUniform) {
  EXPECT_LT(HashToUnit(0xffffffffu), 1.0f);
  EXPECT_EQ(HashToUnit(0u), 0.0f);
  const int samples = 100000, bins = 10;
  int hist[bins] = {};
  double mean = 0;
  for (int i = 0; i < samples; ++i) {
    const float u = Uniform01<float>(42u, static_cast<uint32_t>(i / 100), static_cast<uint32_t>(i % 100));
    ASSERT_GE(u, 0.0f);
    ASSERT_LT(u, 1.0f);
    ++hist[static_cast<int>(u * bins)];
    mean += u;
  }
  for (int b = 0; b < bins; ++b) EXPECT_NEAR(hist[b], samples / bins, 0.05 * samples / bins) << b;
  EXPECT_NEAR(mean / samples, 0.5, 0.005);
  EXPECT_NE(Hash(1, 2, 3), Hash(2, 2, 3));
  EXPECT_NE(Hash(1, 2, 3), Hash(1, 3, 3));
  EXPECT_NE(Hash(1, 2, 3), Hash(1, 2, 4));
  EXPECT_EQ(Hash(1, 2, 3), Hash(1, 2, 3));
}

TEST(RayMathTest, ZeroDensityShowsTheShells) {
  std::mt19937 rng(17);
  TestScene s(rng);
  for (int64_t c = 0; c < 64; ++c) s.x[GridParam(c, 3)] = 0;
  const double e0[4] = {0.9, 0.2, 0.1, 0.3}, e1[4] = {0.1, 0.6, 0.8, 0.5};  // e1's a is ignored
  for (int64_t i = GridParamCount(4); i < static_cast<int64_t>(s.x.size()); ++i) {
    // Not (outer ? e1 : e0)[i % 4]: GCC 12 with any UBSan arithmetic check reads that as
    // element 0 (seen as a = 0.9 instead of 0.3 under -fsanitize=shift).
    const double* e = i >= ShellParam(4, 4, 1, 0, 0, 0, 0) ? e1 : e0;
    s.x[i] = e[i % 4];
  }
  const double target[3] = {0, 0, 0};
  for (int t = 0; t < 10; ++t) {
    const RayOutput<double> out = Forward(s.vol, RandomCameraRay(s, rng), Jitter{1, 2, true, true}, target, 0.1);
    EXPECT_DOUBLE_EQ(out.t_box, 1);
    EXPECT_NEAR(out.residual[3], 0, 1e-15);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(out.h[c], e0[3] * e0[c] + (1 - e0[3]) * e1[c], 1e-14);
  }
}

TEST(RayMathTest, DenseFrontCellHidesEverythingBehind) {
  const int n = 4;
  BoxFrame<double> box{{0, 0, 0}, {{1, 0, 0, 0, 1, 0, 0, 0, 1}}, {4, 4, 4}};  // grid = local + 2
  std::vector<double> x(ParamCount(n, 2, 1), 0.5);
  for (int64_t c = 0; c < n * n * n; ++c) x[GridParam(c, 3)] = 0;
  const double c0[3] = {0.9, 0.1, 0.4};
  for (int i : {0, 1})
    for (int ch = 0; ch < 3; ++ch) x[GridParam(GridCell(n, i, 1, 2), ch)] = c0[ch];
  x[GridParam(GridCell(n, 0, 1, 2), 3)] = 1e3;
  VolumeView<double> vol{x.data(), n, box.size, 1, 2, {0, 0, 0}, {10}};
  // Along +x through the centres of row (j, k) = (1, 2): grid (-1, 1.5, 2.5).
  const BoxRay<double> ray = ToBoxRay(box, n, V3{-3, -0.5, 0.5}, V3{1, 0, 0});
  const double target[3] = {0, 0, 0};
  const RayOutput<double> out = Forward(vol, ray, Jitter{3, 4, true, true}, target, 0.1);
  EXPECT_LT(out.t_box, 1e-100);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(out.h[c], c0[c], 1e-12);
  EXPECT_NEAR(out.residual[3], 0, 1e-12);  // lambda (1 - 4 * 0.25)
}

}  // namespace
}  // namespace perf::recon
