// Data parallelism without MPI: ranks as threads of one process (thread_group.h, a
// Communicator over shared memory), each with its own CPU backend and its share of a synthetic
// scene's photos, against one backend with every photo. The passes' sums, the solver's steps and
// the ranks' parameters must agree; the photo shares must cover every photo once.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "common/comm.h"
#include "common/errors.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/backends/distributed_backend.h"
#include "recon_cuda/solve/solver.h"
#include "tests/recon/synthetic_scene.h"
#include "tests/recon/thread_group.h"

namespace perf::recon {
namespace {

const test::SyntheticScene& Scene() {
  static const test::SyntheticScene scene(32, 16, 12, 24, 4);  // 12 views of 24 x 24, 3 held out
  return scene;
}

// Rank `rank` of `size`'s rays: its share of the training photos, numbered among all ranks' rays.
RaySet RanksRays(Communicator& comm) {
  const std::vector<PosedImage>& train = Scene().train;
  std::vector<double> pixels;
  for (const PosedImage& im : train) pixels.push_back(static_cast<double>(im.image.width) * im.image.height);
  const IndexRange mine = ContiguousShare(pixels, comm.rank(), comm.size());
  RaySet rays = MakeRaySet(std::vector<PosedImage>(train.begin() + static_cast<ptrdiff_t>(mine.begin),
                                                   train.begin() + static_cast<ptrdiff_t>(mine.end)));
  rays.first_index = comm.ShareOf(rays.size()).first;
  return rays;
}

TEST(ContiguousShare, CoversEveryItemOnceInBlocksOfAboutEqualWeight) {
  for (int n : {1, 2, 5, 12, 87}) {
    for (int size : {1, 2, 3, 4, 8}) {
      std::vector<double> w(static_cast<size_t>(n));
      for (int i = 0; i < n; ++i) w[static_cast<size_t>(i)] = 1.0 + (i % 3);  // uneven weights
      size_t next = 0;
      double total = 0, heaviest = 0;
      for (double x : w) total += x;
      for (int r = 0; r < size; ++r) {
        const IndexRange s = ContiguousShare(w, r, size);
        EXPECT_EQ(s.begin, next) << n << " items, rank " << r << " of " << size;
        EXPECT_LE(s.begin, s.end);
        if (n >= size) {
          EXPECT_GT(s.size(), 0u) << n << " items, rank " << r << " of " << size;
        }
        double mine = 0;
        for (size_t i = s.begin; i < s.end; ++i) mine += w[i];
        heaviest = std::max(heaviest, mine);
        next = s.end;
      }
      EXPECT_EQ(next, static_cast<size_t>(n));
      // No block exceeds an equal share by more than one item's weight (3 at most), where
      // every block can hold an item.
      if (n >= size) {
        EXPECT_LE(heaviest, total / size + 3.0 + 1e-9) << n << " items, " << size << " ranks";
      }
    }
  }
}

TEST(DistributedBackend, PassesSumToTheSingleProcessPasses) {
  const test::SyntheticScene& scene = Scene();
  const VolumeShape shape{16, 8, 2};
  const std::vector<float> x = InitialParams(shape, scene.geometry, InitOptions{});
  const int64_t params = shape.ParamCount();
  // One process, every ray.
  const RaySet all = MakeRaySet(scene.train);
  std::unique_ptr<Backend> one = MakeCpuBackend({});
  one->SetLevel(LevelProblem{shape, scene.geometry, &all, {}}, 4);
  one->Upload(0, x);
  const RaySubset every_seventh{7, 3};  // 576 rays a photo: the offset moves from rank to rank
  const PassStats lin1 = one->Linearize(0, 77u, 1, 2, every_seventh);
  std::vector<float> p(static_cast<size_t>(params));
  for (size_t i = 0; i < p.size(); ++i) p[i] = std::sin(0.37f * static_cast<float>(i));
  one->Upload(3, p);
  one->MultiplyJtJ(3, 0);  // into x's slot: x is not needed after Linearize here
  std::vector<float> g1(p.size()), d1(p.size()), jtjp1(p.size());
  one->Download(1, g1);
  one->Download(2, d1);
  one->Download(0, jtjp1);
  one->Upload(0, x);
  const PassStats cost1 = one->Cost(0, 78u, every_seventh);

  for (int size : {2, 3}) {
    test::ThreadGroup group(size);
    std::vector<std::vector<float>> g(size), d(size), jtjp(size);
    std::vector<PassStats> lin(static_cast<size_t>(size)), cost(static_cast<size_t>(size));
    group.Run([&](Communicator& comm) {
      const RaySet rays = RanksRays(comm);
      DistributedBackend b(MakeCpuBackend({.threads = 1}), &comm);
      b.SetLevel(LevelProblem{shape, scene.geometry, &rays, {}}, 4);
      b.Upload(0, x);
      const size_t r = static_cast<size_t>(comm.rank());
      lin[r] = b.Linearize(0, 77u, 1, 2, every_seventh);
      b.Upload(3, p);
      b.MultiplyJtJ(3, 0);
      g[r].resize(p.size());
      d[r].resize(p.size());
      jtjp[r].resize(p.size());
      b.Download(1, g[r]);
      b.Download(2, d[r]);
      b.Download(0, jtjp[r]);
      b.Upload(0, x);
      cost[r] = b.Cost(0, 78u, every_seventh);
      EXPECT_GT(b.bytes_summed(), 3 * params * 4);  // g, diag and J^T J p at least
    });
    for (int r = 0; r < size; ++r) {
      SCOPED_TRACE(StrCat(size, " ranks, rank ", r));
      EXPECT_EQ(lin[r].rays, lin1.rays);
      EXPECT_EQ(lin[r].samples, lin1.samples);
      EXPECT_NEAR(lin[r].cost, lin1.cost, 1e-9 * lin1.cost);
      EXPECT_NEAR(lin[r].subset_cost, lin1.subset_cost, 1e-9 * lin1.subset_cost);
      EXPECT_EQ(cost[r].rays, cost1.rays);
      EXPECT_NEAR(cost[r].cost, cost1.cost, 1e-9 * cost1.cost);
      double worst = 0, scale = 0;
      for (size_t i = 0; i < p.size(); ++i) {
        const auto rel = [](float a, float b) { return std::abs(static_cast<double>(a) - b) / (1 + std::abs(b)); };
        worst = std::max({worst, rel(g[r][i], g1[i]), rel(d[r][i], d1[i]), rel(jtjp[r][i], jtjp1[i])});
        scale = std::max(scale, static_cast<double>(std::abs(g1[i])));
        // Every rank holds the same bits.
        ASSERT_EQ(g[r][i], g[0][i]) << i;
        ASSERT_EQ(jtjp[r][i], jtjp[0][i]) << i;
      }
      EXPECT_GT(scale, 0);
      EXPECT_LT(worst, 1e-4);  // float sums in another order
    }
  }
}

TEST(DistributedBackend, ASolveOnThreeRanksFollowsTheSingleProcess) {
  const test::SyntheticScene& scene = Scene();
  const VolumeShape shape{16, 8, 2};
  const std::vector<float> start = InitialParams(shape, scene.geometry, InitOptions{});
  SolverOptions so;
  so.max_iterations = 4;
  so.line_search_ray_stride = 5;  // subsets follow the global ray index (576 rays a photo)
  so.smooth_grid = 0.1;           // the smoothness term is replicated, not summed
  so.smooth_shells = 0.1;
  const RaySet all = MakeRaySet(scene.train);
  std::unique_ptr<Backend> one = MakeCpuBackend({});
  one->SetLevel(LevelProblem{shape, scene.geometry, &all, {}}, RequiredVectors(so.type));
  std::vector<float> x1 = start;
  SolverSummary s1;
  Solve(so, one.get(), &x1, {}, &s1);

  test::ThreadGroup group(3);
  std::vector<SolverSummary> s(3);
  std::vector<std::vector<float>> x(3, start);
  group.Run([&](Communicator& comm) {
    const RaySet rays = RanksRays(comm);
    DistributedBackend b(MakeCpuBackend({.threads = 1}), &comm);
    b.SetLevel(LevelProblem{shape, scene.geometry, &rays, {}}, RequiredVectors(so.type));
    const size_t r = static_cast<size_t>(comm.rank());
    Solve(so, &b, &x[r], {}, &s[r]);
    b.CheckInStep(VectorsOf(so.type).params);
  });
  for (int r = 0; r < 3; ++r) {
    SCOPED_TRACE(StrCat("rank ", r));
    ASSERT_EQ(s[r].iterations, s1.iterations);
    for (int it = 0; it < s1.iterations; ++it) {
      EXPECT_NEAR(s[r].per_iteration[it].cost, s1.per_iteration[it].cost, 1e-4 * s1.per_iteration[it].cost) << it;
      EXPECT_EQ(s[r].per_iteration[it].accepted, s1.per_iteration[it].accepted) << it;
    }
    EXPECT_NEAR(s[r].final_cost, s1.final_cost, 1e-4 * s1.final_cost);
    EXPECT_EQ(x[r], x[0]) << "the ranks' parameters differ";
  }
  EXPECT_LT(s1.final_cost, 0.5 * s1.initial_cost);  // the solve did something
}

}  // namespace
}  // namespace perf::recon
