// The smoothness residuals (smoothness.h): the neighbour relation (every texel has 4, across the
// cube-map seams too, and the relation is symmetric; a sparse grid's neighbours are the dense
// grid's stored ones), the backend's term against Ceres (each pair a residual block) and against
// central differences, and the solver with it: smoother shells where the photos do not say
// otherwise.
#include "recon_cuda/core/smoothness.h"

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>

#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/solve/solver.h"
#include "tests/recon/recon_test_util.h"

namespace perf::recon {
namespace {

TEST(Smoothness, EveryTexelHasFourNeighboursSymmetricallyAcrossSeams) {
  for (int m : {1, 2, 3, 8}) {
    SmoothnessLayout l;
    l.m = m;
    l.num_shells = 2;
    const int64_t per_shell = 6 * int64_t{m} * m;
    std::multiset<std::pair<int64_t, int64_t>> pairs;
    for (int64_t t = 0; t < 2 * per_shell; ++t) {
      int64_t nbr[4];
      ShellNeighbours(l, t, nbr);
      for (int64_t q : nbr) {
        EXPECT_NE(q, t) << "m " << m;
        EXPECT_EQ(q / per_shell, t / per_shell) << "a neighbour in another shell, m " << m;
        pairs.insert({t, q});
      }
      if (m > 1) {
        EXPECT_EQ(std::set<int64_t>(nbr, nbr + 4).size(), 4u) << "texel " << t << ", m " << m;
      }
    }
    for (const auto& [a, b] : pairs) EXPECT_EQ(pairs.count({a, b}), pairs.count({b, a})) << a << " " << b << ", m " << m;
    // Each face edge pairs texel for texel with its neighbouring face's: 12 edges x m pairs.
    int seam = 0;
    for (const auto& [a, b] : pairs) seam += a / (int64_t{m} * m) != b / (int64_t{m} * m) && a < per_shell;
    EXPECT_EQ(seam, 2 * 12 * m) << "m " << m;  // each pair seen from both ends
  }
}

TEST(Smoothness, SparseGridNeighboursAreTheDenseGridsStoredOnes) {
  const int n = 16;
  std::vector<uint8_t> active(8, 0);
  active[0] = active[1] = active[6] = 1;  // two touching bricks and one alone
  const auto bricks = std::make_shared<const BrickGrid>(MakeBrickGrid(n, active));
  const VolumeShape sparse = VolumeShape{n, 2, 1}.WithBricks(bricks), dense{n, 2, 1};
  const SmoothnessLayout ls = MakeSmoothnessLayout(sparse), ld = MakeSmoothnessLayout(dense);
  int64_t cells = 0, across_bricks = 0;
  ForEachStoredCell(sparse, [&](int i, int j, int k, int64_t cell) {
    ++cells;
    int64_t got[6], want[6];
    const int ng = GridNeighbours(ls, cell, got);
    const int nd = GridNeighbours(ld, GridCell(n, i, j, k), want);
    std::set<int64_t> expected;  // the dense neighbours whose bricks are active, as stored cells
    for (int q = 0; q < nd; ++q) {
      const int64_t c = want[q];
      const int64_t s = StoredCell(sparse, static_cast<int>(c % n), static_cast<int>(c / n % n), static_cast<int>(c / (n * n)));
      if (s >= 0) expected.insert(s);
    }
    EXPECT_EQ(std::set<int64_t>(got, got + ng), expected) << i << " " << j << " " << k;
    for (int q = 0; q < ng; ++q) across_bricks += got[q] / kBrickCells != cell / kBrickCells;
  });
  EXPECT_EQ(cells, 3 * kBrickCells);
  EXPECT_EQ(across_bricks, 2 * 64);  // bricks 0 and 1 share one 8 x 8 face
}

// A level of the CPU backend without rays, x random in the valid range, with spherical harmonics
// of degree 1 (smoothed as the colour) and one photo's exposure (whose weight is a prior's:
// smoothness.h).
struct SmoothLevel {
  test::TinyProblem p{5, 8, 3, 1, 2, 2};
  std::unique_ptr<Backend> b = MakeCpuBackend({});
  SmoothnessWeights w{0.7f, 0.3f, 1.3f, 0.9f, 0.5f};
  SmoothLevel() {
    p.AddSh(1, 2);
    p.AddExposures(3);
    b->SetLevel(LevelProblem{p.shape, p.geometry, nullptr, {}}, 4);
    b->Upload(0, p.x);
  }
  std::vector<float> Get(VecId v) const {
    std::vector<float> h(p.shape.ParamCount());
    b->Download(v, h);
    return h;
  }
};

// One exposure's prior residual sqrt(w) x.
struct PriorResidual {
  double sqrt_w;
  template <class T>
  bool operator()(const T* a, T* r) const {
    r[0] = T(sqrt_w) * a[0];
    return true;
  }
};

// One pair's residual sqrt(w) (x_a - x_b).
struct PairResidual {
  double sqrt_w;
  template <class T>
  bool operator()(const T* a, const T* b, T* r) const {
    r[0] = T(sqrt_w) * (a[0] - b[0]);
    return true;
  }
};

TEST(Smoothness, CostGradientAndDiagonalMatchCeres) {
  SmoothLevel s;
  const int64_t n = s.p.shape.ParamCount();
  s.b->Fill(1, 0.f);
  s.b->Fill(2, 0.f);
  s.b->AddSmoothness(0, s.w, 1, 2);
  const double cost = s.b->SmoothnessCost(0, s.w);
  const std::vector<float> g = s.Get(1), diag = s.Get(2);

  // Ceres: one residual block per pair (a < b), each parameter its own block.
  std::vector<double> x(s.p.x.begin(), s.p.x.end());
  ceres::Problem::Options po;
  ceres::Problem problem(po);
  const SmoothnessLayout layout = MakeSmoothnessLayout(s.p.shape);
  std::vector<double> degree(n, 0.0);
  for (int64_t i = 0; i < n; ++i) problem.AddParameterBlock(&x[i], 1);
  int64_t pairs = 0;
  for (int64_t i = s.p.shape.ExposureStart(); i < n; ++i) {
    const double w = s.w.Of(KindOf(s.p.shape, i));
    EXPECT_EQ(w, 0.5);
    degree[i] = w;
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PriorResidual, 1, 1>(new PriorResidual{std::sqrt(w)}),
                             nullptr, &x[i]);
  }
  for (int64_t i = 0; i < s.p.shape.ExposureStart(); ++i) {
    int64_t nbr[6];
    const int count = ParamNeighbours(layout, i, nbr);
    const double w = s.w.Of(KindOf(s.p.shape, i));
    for (int k = 0; k < count; ++k) {
      EXPECT_EQ(KindOf(s.p.shape, nbr[k]), KindOf(s.p.shape, i));
      degree[i] += w;
      if (nbr[k] < i) continue;
      ++pairs;
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PairResidual, 1, 1, 1>(new PairResidual{std::sqrt(w)}),
                               nullptr, &x[i], &x[nbr[k]]);
    }
  }
  EXPECT_GT(pairs, 3 * 8 * 8 * 7 * 4);  // the grid's pairs alone
  double ceres_cost = 0;
  std::vector<double> ceres_g;
  ASSERT_TRUE(problem.Evaluate(ceres::Problem::EvaluateOptions(), &ceres_cost, nullptr, &ceres_g, nullptr));
  EXPECT_NEAR(cost, ceres_cost, 1e-5 * ceres_cost);
  ASSERT_EQ(static_cast<int64_t>(ceres_g.size()), n);
  for (int64_t i = 0; i < n; ++i) {
    EXPECT_NEAR(g[i], ceres_g[i], 1e-4 * (1 + std::abs(ceres_g[i]))) << i;
    EXPECT_FLOAT_EQ(diag[i], static_cast<float>(degree[i])) << i;
  }
}

TEST(Smoothness, GradientIsTheCentralDifferenceAndTheHessianIsSymmetric) {
  SmoothLevel s;
  const int64_t n = s.p.shape.ParamCount();
  s.b->Fill(1, 0.f);
  s.b->AddSmoothness(0, s.w, 1, kNoVector);
  const std::vector<float> g = s.Get(1);
  std::mt19937 rng(9);
  std::uniform_int_distribution<int64_t> pick(0, n - 1);
  for (int t = 0; t < 48; ++t) {
    // The exposure's values, the last cell's spherical harmonics, and any.
    const int64_t i = t < kExposureValues ? n - 1 - t : t < 12 ? s.p.shape.ExposureStart() - 1 - t : pick(rng);
    std::vector<float> x = s.p.x;
    const float h = 1e-2f;  // the cost is quadratic: central differences are exact up to rounding
    x[i] += h;
    s.b->Upload(3, x);
    const double up = s.b->SmoothnessCost(3, s.w);
    x[i] -= 2 * h;
    s.b->Upload(3, x);
    const double down = s.b->SmoothnessCost(3, s.w);
    EXPECT_NEAR(g[i], (up - down) / (2 * h), 2e-3 * (1 + std::abs(g[i]))) << i;
  }
  // <q, L p> = <p, L q> for random p, q.
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<float> p(n), q(n);
  for (int64_t i = 0; i < n; ++i) {
    p[i] = u(rng);
    q[i] = u(rng);
  }
  s.b->Upload(0, p);
  s.b->Upload(1, q);
  s.b->Fill(2, 0.f);
  s.b->Fill(3, 0.f);
  s.b->AddSmoothness(0, s.w, 2, kNoVector);
  s.b->AddSmoothness(1, s.w, 3, kNoVector);
  const double qlp = s.b->Dot(1, 2), plq = s.b->Dot(0, 3);
  EXPECT_NEAR(qlp, plq, 1e-4 * std::abs(qlp));
  // and p^T L p / 2 is the cost at p.
  EXPECT_NEAR(s.b->SmoothnessCost(0, s.w), 0.5 * s.b->Dot(0, 2), 1e-4 * s.b->Dot(0, 2));
}

TEST(Smoothness, SolverWithSmoothShellsFitsSmootherShells) {
  // The tiny problem's rays see the shells at a few texels only: with smoothness the unseen
  // texels follow their seen neighbours instead of keeping their random start.
  const test::TinyProblem p(11, 4, 4, 3, 6, 5);
  const auto roughness = [&](const std::vector<float>& x) {
    const SmoothnessLayout l = MakeSmoothnessLayout(p.shape);
    double r = 0;
    for (int64_t i = p.shape.GridParamCount(); i < p.shape.ParamCount(); ++i) {
      int64_t nbr[6];
      const int c = ParamNeighbours(l, i, nbr);
      for (int k = 0; k < c; ++k) r += (x[i] - x[nbr[k]]) * (x[i] - x[nbr[k]]);
    }
    return r;
  };
  std::vector<double> rough;
  for (double smooth : {0.0, 1.0}) {
    auto b = MakeCpuBackend({});
    SolverOptions o;
    o.max_iterations = 6;
    o.smooth_shells = smooth;
    o.line_search_ray_stride = 1;
    b->SetLevel(LevelProblem{p.shape, p.geometry, &p.rays, {}}, RequiredVectors(o.type));
    std::vector<float> x = p.x;
    SolverSummary summary;
    Solve(o, b.get(), &x, nullptr, &summary);
    EXPECT_LT(summary.final_cost, summary.initial_cost) << summary.BriefReport();
    EXPECT_EQ(summary.smoothness.Any(), smooth > 0);
    EXPECT_EQ(summary.smoothness.grid_colour, 0.f);
    rough.push_back(roughness(x));
  }
  EXPECT_LT(rough[1], 0.5 * rough[0]) << "start " << roughness(p.x);
}

}  // namespace
}  // namespace perf::recon
