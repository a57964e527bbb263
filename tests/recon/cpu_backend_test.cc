// The CPU backend's passes against a dense Jacobian from the double-precision per-ray math:
// cost, J^T r, the exact diag(J^T J), J^T J p (cached and recomputed partials), the line-search
// cost on a subset, thread-count independence, and the render path.
#include "recon_cuda/backends/cpu_backend.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <span>

#include "common/errors.h"

#include "recon_cuda/backends/cpu_jacobian_record.h"
#include "recon_cuda/data/volume.h"
#include "tests/recon/recon_test_util.h"

namespace perf::recon {
namespace {

using test::DenseJacobian;
using test::TinyProblem;

// Float pass vs double reference: each entry within 2e-4 of the largest entry (float sums over
// a few hundred contributions) plus 1e-4 relative.
void ExpectClose(const std::vector<float>& got, const std::vector<double>& want, const char* what) {
  test::ExpectAllClose(got, want, 2e-4, 1e-4, what);
}

// The tests against the dense Jacobian check the exact record; the compact ones have their own
// tests.
using cpu::RecordKind;
std::unique_ptr<Backend> Cpu(int threads, bool cache = true, RecordKind record = RecordKind::kExact,
                             int64_t max_memory = 0) {
  CpuBackendOptions o;
  o.threads = threads;
  o.cache_jacobian = cache;
  o.compact_jacobian = record != RecordKind::kExact;
  o.merged_jacobian = record == RecordKind::kMerged;
  o.max_memory = max_memory;
  return MakeCpuBackend(o);
}
const char* Name(RecordKind k) {
  return k == RecordKind::kExact ? "exact" : k == RecordKind::kCompact ? "compact samples" : "merged cells";
}
constexpr RecordKind kRecords[] = {RecordKind::kExact, RecordKind::kCompact, RecordKind::kMerged};

enum : VecId { kX, kG, kD, kP, kOut, kVectors };

TEST(CpuBackendTest, LinearizeMatchesTheDenseJacobian) {
  const TinyProblem p(1);
  for (const bool pixel_jitter : {true, false}) {
    SCOPED_TRACE(pixel_jitter ? "rays jittered in their pixels" : "rays through pixel centres");
    auto b = Cpu(2);
    b->SetLevel(p.Level(0.1f, pixel_jitter), kVectors);
    b->Upload(kX, p.x);
    const uint32_t seed = 77;
    const PassStats s = b->Linearize(kX, seed, kG, kD);
    const DenseJacobian j(p, p.x, seed, 0.1, true, pixel_jitter);
    EXPECT_NEAR(s.cost, j.Cost(), 1e-5 * j.Cost());
    EXPECT_EQ(s.rays, p.rays.size());
    EXPECT_GT(s.samples, p.rays.size());
    std::vector<float> g(p.shape.ParamCount()), d(p.shape.ParamCount());
    b->Download(kG, g);
    b->Download(kD, d);
    ExpectClose(g, j.Jtr(), "J^T r");
    ExpectClose(d, j.Diag(), "diag(J^T J)");
    // The other choice of ray is a different problem: its cost differs.
    const DenseJacobian other(p, p.x, seed, 0.1, true, !pixel_jitter);
    EXPECT_GT(std::abs(s.cost - other.Cost()), 1e-4 * j.Cost());
  }
}

// Rays with the photos' alpha: the fourth residual is w ((1 - T_box) - alpha) with w =
// alpha_weight, not lambda (ray_math.h AuxResidual); Linearize and J^T J p against the dense
// Jacobian of that residual.
TEST(CpuBackendTest, AlphaResidualMatchesTheDenseJacobian) {
  TinyProblem p(4);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (int64_t i = 0; i < p.rays.size(); ++i) p.rays.alphas.push_back(i % 3 == 0 ? 0.f : u(rng));
  auto b = Cpu(2);
  LevelProblem level = p.Level(0.05f);
  level.residuals.alpha_weight = 0.3f;
  b->SetLevel(level, kVectors);
  ASSERT_TRUE(UsesAlpha(b->level()));
  b->Upload(kX, p.x);
  const uint32_t seed = 21;
  const PassStats s = b->Linearize(kX, seed, kG, kD);
  const DenseJacobian j(p, p.x, seed, 0.3);
  EXPECT_NEAR(s.cost, j.Cost(), 1e-5 * j.Cost());
  std::vector<float> g(p.shape.ParamCount()), d(p.shape.ParamCount()), pv(p.shape.ParamCount()), out(g.size());
  b->Download(kG, g);
  b->Download(kD, d);
  ExpectClose(g, j.Jtr(), "J^T r");
  ExpectClose(d, j.Diag(), "diag(J^T J)");
  for (size_t i = 0; i < pv.size(); ++i) pv[i] = u(rng) - 0.5f;
  b->Upload(kP, pv);
  b->MultiplyJtJ(kP, kOut);
  b->Download(kOut, out);
  ExpectClose(out, j.Jtu(j.Jp(std::vector<double>(pv.begin(), pv.end()))), "J^T J p");
  // With use_alpha off the same rays give the paper's residual: another cost.
  LevelProblem paper = p.Level();
  paper.residuals.use_alpha = false;
  b->SetLevel(paper, kVectors);
  b->Upload(kX, p.x);
  EXPECT_GT(std::abs(b->Cost(kX, seed).cost - s.cost), 1e-4 * s.cost);
}

TEST(CpuBackendTest, DiagonalMergesVisitsOfTheSameCell) {
  // Squaring each visit on its own drops the cross terms between neighbouring samples that share
  // a cell (of either sign: sigma's partials change sign along a ray) and gives a visibly
  // different diagonal; the backend's must be the exact one.
  const TinyProblem p(2);
  const DenseJacobian j(p, p.x, 5, 0.1);
  const std::vector<double> exact = j.Diag();
  std::vector<double> naive(exact.size(), 0.0);
  for (const auto& [i, v] : j.naive_diag_terms) naive[i] += v;
  auto b = Cpu(1);
  b->SetLevel(p.Level(), kVectors);
  b->Upload(kX, p.x);
  b->Linearize(kX, 5, kG, kD);
  std::vector<float> d(p.shape.ParamCount());
  b->Download(kD, d);
  double sum_exact = 0, sum_naive = 0, sum_got = 0;
  for (size_t i = 0; i < exact.size(); ++i) {
    sum_exact += exact[i];
    sum_naive += naive[i];
    sum_got += d[i];
  }
  EXPECT_NEAR(sum_got, sum_exact, 1e-4 * sum_exact);
  EXPECT_GT(std::abs(sum_exact - sum_naive), 0.1 * sum_exact);
}

TEST(CpuBackendTest, JtJpMatchesTheDenseJacobianCachedAndRecomputed) {
  const TinyProblem p(3);
  const uint32_t seed = 11;
  const DenseJacobian j(p, p.x, seed, 0.1);
  const std::vector<float> pv = test::RandomDirection(p.shape, 4);
  const std::vector<double> want = j.Jtu(j.Jp(std::vector<double>(pv.begin(), pv.end())));
  for (bool cache : {true, false}) {
    auto b = Cpu(2, cache);
    b->SetLevel(p.Level(), kVectors);
    EXPECT_EQ(b->CachesJacobian(), cache);
    b->Upload(kX, p.x);
    b->Upload(kP, pv);
    b->Linearize(kX, seed, kG, kD);
    b->MultiplyJtJ(kP, kOut);
    std::vector<float> out(p.shape.ParamCount());
    b->Download(kOut, out);
    ExpectClose(out, want, cache ? "J^T J p (cached)" : "J^T J p (recomputed)");
  }
}

// ReleaseJacobian (the hierarchy's, after a level's solve) frees the record: MultiplyJtJ is then
// refused until a Linearize, which records it again, and the product is the one before, bit for
// bit on one thread (every kind of record). With keep_room the merged cells' room stays for the
// next level, which records into it the same (SetLevel again, as the hierarchy does).
TEST(CpuBackendTest, AReleasedJacobianIsRecordedAgain) {
  const TinyProblem p(3);
  const std::vector<float> pv = test::RandomDirection(p.shape, 4);
  for (const RecordKind record : kRecords) {
    for (const bool keep_room : {false, true}) {
      SCOPED_TRACE(testing::Message() << Name(record) << (keep_room ? ", room kept" : ""));
      auto b = Cpu(1, true, record);
      b->SetLevel(p.Level(), kVectors);
      b->Upload(kX, p.x);
      b->Upload(kP, pv);
      std::vector<float> before(p.shape.ParamCount()), after(p.shape.ParamCount());
      b->Linearize(kX, 11, kG, kD);
      b->MultiplyJtJ(kP, kOut);
      b->Download(kOut, before);
      b->ReleaseJacobian(keep_room);
      EXPECT_THROW(b->MultiplyJtJ(kP, kOut), InternalError);
      if (keep_room) {
        b->SetLevel(p.Level(), kVectors);
        b->Upload(kX, p.x);
        b->Upload(kP, pv);
      }
      b->Linearize(kX, 11, kG, kD);
      b->MultiplyJtJ(kP, kOut);
      b->Download(kOut, after);
      EXPECT_EQ(after, before);
      EXPECT_GT(*std::max_element(after.begin(), after.end()), 0.f);
    }
  }
}

// J^T J p of a backend keeping `record` on p (the fourth residual weighted lambda) for pv, then
// after RestrictJacobian to `free` for held_p (with its output masked by `free`, as the solver's).
struct RecordedProducts {
  std::vector<float> out[2];  // [restricted]
  PassStats stats[2];
  RecordedProducts(const TinyProblem& p, float lambda, RecordKind record, const std::vector<float>& pv,
                   const std::vector<float>& free, const std::vector<float>& held_p, bool mask) {
    auto b = Cpu(2, true, record);
    b->SetLevel(p.Level(lambda), kVectors);
    b->Upload(kX, p.x);
    b->Upload(kP, pv);
    b->Linearize(kX, 11, kG, kD);
    for (const bool restricted : {false, true}) {
      if (restricted) {
        b->Upload(kG, free);
        b->Upload(kP, held_p);
        b->RestrictJacobian(kG);
      }
      stats[restricted] = b->MultiplyJtJ(kP, kOut);
      out[restricted].resize(p.shape.ParamCount());
      b->Download(kOut, out[restricted]);
      if (restricted && mask) {
        for (size_t i = 0; i < free.size(); ++i) out[restricted][i] *= free[i];
      }
    }
  }
};

// The records' tests hold every density (RestrictJacobian then drops what reaches only empty,
// held cells): the first half of p's cells is made empty; `free` holds the densities, held_p is
// pv with 0 on them.
void HoldDensities(TinyProblem* p, const std::vector<float>& pv, std::vector<float>* free,
                   std::vector<float>* held_p) {
  free->assign(p->shape.ParamCount(), 1.f);
  *held_p = pv;
  for (int64_t c = 0; c < p->shape.StoredCells(); ++c) {
    (*free)[GridParam(c, 3)] = 0.f;
    (*held_p)[GridParam(c, 3)] = 0.f;
    if (2 * c < p->shape.StoredCells()) p->x[GridParam(c, 3)] = 0.f;
  }
}

// A compact record's J^T J p against the exact record's, on the volume alone and with exposures
// and poses, the fourth residual weighted 0.1 and 100, on every parameter and restricted.
void ExpectCloseToTheExactRecord(RecordKind record) {
  const bool merged = record == RecordKind::kMerged;
  TinyProblem posed(3);
  posed.AddExposures(5);
  posed.AddPoses(6);
  for (TinyProblem p : {TinyProblem(3), posed}) {
    SCOPED_TRACE(p.shape.poses > 0 ? "poses refined" : "volume only");
    const std::vector<float> pv = test::RandomDirection(p.shape, 4);
    std::vector<float> free, held_p;
    HoldDensities(&p, pv, &free, &held_p);
    // Merged, on the volume's entries: the exact record but for the order of float sums, unless
    // the rays' bfloat16 pose rows reach them (through J p).
    const double volume_tol = merged && p.shape.poses == 0 ? 1e-5 : 3e-3;
    for (const float lambda : {0.1f, 100.f}) {
      SCOPED_TRACE(lambda);
      const RecordedProducts exact_run(p, lambda, RecordKind::kExact, pv, free, held_p, merged);
      const RecordedProducts run(p, lambda, record, pv, free, held_p, merged);
      for (const bool restricted : {false, true}) {
        SCOPED_TRACE(restricted ? "restricted" : "every parameter");
        const std::vector<float>& exact = exact_run.out[restricted];
        const std::vector<float>& got = run.out[restricted];
        // PassStats::samples counts a merged record's cells: several a sample.
        if (merged) EXPECT_GT(run.stats[restricted].samples, 2 * exact_run.stats[restricted].samples);
        else EXPECT_EQ(run.stats[restricted].samples, exact_run.stats[restricted].samples);
        EXPECT_GT(run.stats[restricted].samples, 100);
        // The volume's entries, and the photos' (exposures and poses, on their own scale).
        const auto photos = static_cast<std::ptrdiff_t>(p.shape.ExposureStart());
        test::ExpectAllClose(std::vector<float>(got.begin(), got.begin() + photos),
                             std::vector<double>(exact.begin(), exact.begin() + photos), volume_tol, volume_tol,
                             "compact J^T J p, the volume");
        if (!merged) {
          EXPECT_NE(got, exact);  // rounded: not the exact record
        }
        if (p.shape.poses > 0) {
          test::ExpectAllClose(std::vector<float>(got.begin() + photos, got.end()),
                               std::vector<double>(exact.begin() + photos, exact.end()), 3e-3, 3e-3,
                               "compact J^T J p, exposures and poses");
          const auto at = static_cast<std::ptrdiff_t>(p.shape.PoseStart());
          EXPECT_FALSE(std::equal(got.begin() + at, got.end(), exact.begin() + at));  // rounded too
        }
      }
      EXPECT_LT(run.stats[1].samples, run.stats[0].samples);  // the restriction dropped some
    }
  }
}

// The compact record (CpuBackendOptions::compact_jacobian, the default; sample by sample, as
// levels with spherical harmonics keep it): the same samples (their
// positions recomputed from their march indices; a wrong one would miss by far more than the
// tolerance) with the colour partials rounded to bfloat16 (2^-9 relative each) and dl made from
// the ray's dL/dT_box as Backward makes it, the shells' partials recomputed from the ray's T_box
// and the shells' values at the linearisation point (a T_box 10 % off, or the colour behind a
// shell left at 0, fails it; so does solver_bounds_test's step), and
// the pose rows in bfloat16 (a row read three rays off fails it; the next pixel's is
// within the tolerance), so J^T J p within a few tenths of a percent of the exact record's. With
// the fourth residual weighted 100 its dl^2 terms dominate the densities' entries: a dl off by 1 %
// fails there. With every density held, the compact record re-encodes its march steps in place.
TEST(CpuBackendTest, CompactRecordIsTheExactOneRoundedToBfloat16) { ExpectCloseToTheExactRecord(RecordKind::kCompact); }

// The merged record (CpuBackendOptions::merged_jacobian, the default at degree 0): each ray's cells
// with the sums of its samples' partials times their trilinear weights, in float, beside the
// compact record's shells and bfloat16 pose rows. Without poses J^T J p is the exact record's but
// for the order of float sums (to 1e-5; a cell's sums from the wrong ray, or one sample's weight
// left out, fail it by far); with every density held the dropped cells (merged dc 0 and
// the density held) change nothing on the free entries, the only ones the solver keeps
// (Multiply by the free mask, as RecordedProducts does here).
TEST(CpuBackendTest, MergedRecordIsTheExactOneSummedByCell) { ExpectCloseToTheExactRecord(RecordKind::kMerged); }

// Which record a level keeps (CpuBackendOptions::merged_jacobian): merged cells at degree 0 when
// the level fits in half the memory with them; samples with spherical harmonics (the bands'
// traffic dominates there) or when memory is short. PassStats::samples tells them apart: a merged
// record counts its rays' cells, several a sample.
TEST(CpuBackendTest, MergedCellsOnlyWithoutBandsAndWhereTheyFit) {
  TinyProblem plain(3), banded(3);
  banded.AddSh(1, 8);
  const auto recorded = [](const TinyProblem& p, int64_t max_memory, int64_t* cache_bytes) {
    auto b = Cpu(2, true, RecordKind::kMerged, max_memory);
    *cache_bytes = b->EstimateMemory(p.Level(), kVectors).jacobian_cache;
    b->SetLevel(p.Level(), kVectors);
    b->Upload(kX, p.x);
    b->Upload(kP, test::RandomDirection(p.shape, 4));
    const PassStats lin = b->Linearize(kX, 11, kG, kD);
    EXPECT_TRUE(b->CachesJacobian());
    return std::pair{b->MultiplyJtJ(kP, kOut).samples, lin.samples};
  };
  const int64_t plenty = int64_t{1} << 40;
  int64_t merged_bytes = 0, sample_bytes = 0;
  const auto [cells, samples] = recorded(plain, plenty, &merged_bytes);
  EXPECT_GT(cells, 2 * samples) << "merged cells at degree 0";
  const MemoryEstimate e = Cpu(2)->EstimateMemory(plain.Level(), kVectors);
  // Just too little for half the memory: the level keeps its samples, and says so in its estimate.
  const int64_t tight = 2 * (e.Needed() + merged_bytes) - 1;
  const auto [short_count, short_samples] = recorded(plain, tight, &sample_bytes);
  EXPECT_EQ(short_count, short_samples) << "samples where memory is short";
  EXPECT_LT(sample_bytes, merged_bytes);
  // The estimate is of what is kept: near the recorded cells' 24 bytes each (and the rays' own).
  EXPECT_GT(merged_bytes, cells * 16 / 2);
  EXPECT_LT(merged_bytes, cells * 16 * 3);
  int64_t banded_bytes = 0;
  const auto [banded_count, banded_samples] = recorded(banded, plenty, &banded_bytes);
  EXPECT_EQ(banded_count, banded_samples) << "samples with spherical harmonics";
}

// Given the level's start, the merged record's estimate ends each ray where it turns opaque, as
// Linearize does: far below the estimate without one in a dense volume, and still about what is
// recorded.
TEST(CpuBackendTest, MergedEstimateEndsRaysWhereTheyTurnOpaque) {
  TinyProblem dense(5, 8, 2, 3, 12, 10);
  for (int64_t i = 0; i < dense.shape.ParamCount(); ++i) {
    if (KindOf(dense.shape, i) == ParamKind::kGridDensity) dense.x[i] *= 20.f;
  }
  LevelProblem level = dense.Level();
  level.residuals.stop_transmittance = 1e-3f;
  const auto estimate = [&](std::span<const float> start) {
    LevelProblem l = level;
    l.start = start;
    return Cpu(2, true, RecordKind::kMerged)->EstimateMemory(l, kVectors).jacobian_cache;
  };
  const int64_t blind = estimate({}), seeing = estimate(dense.x);
  auto b = Cpu(2, true, RecordKind::kMerged);
  b->SetLevel(level, kVectors);
  b->Upload(kX, dense.x);
  b->Upload(kP, test::RandomDirection(dense.shape, 4));
  b->Linearize(kX, 11, kG, kD);
  const int64_t cells = b->MultiplyJtJ(kP, kOut).samples, rays = dense.rays.size();
  const int64_t recorded = cells * static_cast<int64_t>(sizeof(cpu::MergedCellJ));
  std::printf("merged record: %lld cells on %lld rays (%lld bytes); estimated %lld bytes with the start, %lld without\n",
              static_cast<long long>(cells), static_cast<long long>(rays), static_cast<long long>(recorded),
              static_cast<long long>(seeing), static_cast<long long>(blind));
  EXPECT_LT(2 * seeing, blind) << "the opaque volume ends its rays early";
  EXPECT_GT(seeing, recorded * 3 / 4);
  EXPECT_LT(seeing, recorded * 2 + rays * 64) << "the cells and the rays' own bytes";
}

// The compact record's march indices, one byte a sample (the steps back from the ray's entry
// before: Backward records a ray back to front), across gaps longer than a byte: bridged by
// fillers (every partial 0, dl too) when recorded, and again when samples are dropped and the
// rest re-encoded in place (KeepRecordedSamples, which DropSkippableSamples runs).
TEST(CpuBackendTest, CompactRecordStepsBridgeLongGaps) {
  using cpu::BlockJ;
  const std::vector<std::vector<int>> ks = {{1401, 1400, 600, 4, 3}, {511, 256, 0}, {}, {70}};
  const std::vector<size_t> entries = {5 + 2 + 3, 3 + 1, 0, 1};  // samples and fillers
  const March<float> m{0.f, 2000.f, 1.f, 2000, true};           // sample k at t = k + 0.5
  const Jitter none{0, 0, false, false};
  const auto partials = [](int k) { return SamplePartials<float>{0.01f * k, {1.f, -2.f, 0.5f * k}, 0.f}; };
  BlockJ b;
  b.Clear(static_cast<int64_t>(ks.size()), VolumeShape(4, 2, 2), RecordKind::kCompact);
  for (size_t r = 0; r < ks.size(); ++r) {
    int last = -1;
    for (int k : ks[r]) b.AppendCompact(static_cast<int64_t>(r), k, partials(k), &last);
    b.end[r] = b.SampleCount();
    b.dl_per_delta[r] = 2.f;
  }
  // The samples of `want` (of every ray) read back in order, with a filler wherever a step is longer.
  const auto expect_samples = [&](const std::vector<std::vector<int>>& want) {
    uint32_t first = 0;
    for (size_t r = 0; r < want.size(); ++r) {
      SCOPED_TRACE(r);
      cpu::RecordedSamples read(b, m, none, static_cast<int64_t>(r), first);
      int last = -1;
      size_t next = 0;
      for (uint32_t j = first; j < b.end[r]; ++j) {
        SamplePartials<float> sp;
        const float t = read.Next(&sp);
        ASSERT_LT(next, want[r].size());
        if (sp.dl == 0.f) {  // a filler: nothing, one full step back
          EXPECT_EQ(last - read.k(), CompactSampleJ::kMaxStep);
          EXPECT_GT(read.k(), want[r][next]);
          EXPECT_EQ(sp.dc, 0.f);
          EXPECT_EQ(sp.ds[2], 0.f);
        } else {
          const int k = want[r][next++];
          EXPECT_EQ(read.k(), k);
          EXPECT_EQ(t, static_cast<float>(k) + 0.5f);
          const SamplePartials<float> p = partials(k);
          EXPECT_EQ(sp.dc, FromBfloat16(ToBfloat16(p.dc)));
          EXPECT_EQ(sp.ds[2], FromBfloat16(ToBfloat16(p.ds[2])));
          EXPECT_EQ(sp.dl, 2.f);
        }
        last = read.k();
      }
      EXPECT_EQ(next, want[r].size());
      first = b.end[r];
    }
  };
  for (size_t r = 0; r < ks.size(); ++r) EXPECT_EQ(b.end[r] - (r ? b.end[r - 1] : 0), entries[r]) << r;
  expect_samples(ks);
  // Drop 600 and 4 of the first ray (1397 steps from 1400 to 3: 5 fillers where there were 7
  // entries) and 256 of the second, in place (KeepRecordedSamples, as DropSkippableSamples does).
  const std::vector<std::vector<int>> kept = {{1401, 1400, 3}, {511, 0}, {}, {70}};
  struct Ray {
    March<float> march;
    Jitter jit;
    size_t r;
  };
  cpu::KeepRecordedSamples([&](size_t r) { return Ray{m, none, r}; },
                           [&](const Ray& ray, float, const SamplePartials<float>& sp, int k) {
                             return sp.dl != 0.f && std::count(kept[ray.r].begin(), kept[ray.r].end(), k) > 0;
                           },
                           &b);
  EXPECT_EQ(b.end[0], 3u + 5u);
  EXPECT_EQ(b.end[1] - b.end[0], 2u + 2u);  // 511 steps: fillers at 256 and 1
  EXPECT_EQ(b.SampleCount(), b.end.back());  // the vectors cut to the entries kept
  EXPECT_EQ(b.steps.size(), b.packed.size());
  expect_samples(kept);
}

// Subsampled Gauss-Newton (SolverOptions::jtj_ray_stride): with jtj = every 3rd ray from an
// offset, MultiplyJtJ is J_S^T J_S p over those rays' rows alone, recorded (only those rays are
// kept) and recomputed, and after RestrictJacobian; the three offsets sum to the full product.
TEST(CpuBackendTest, JtJpOnASubsetOfTheRaysUsesTheirRowsAlone) {
  const TinyProblem p(3);
  const uint32_t seed = 11;
  const DenseJacobian j(p, p.x, seed, 0.1);
  const std::vector<float> pv = test::RandomDirection(p.shape, 4);
  const std::vector<double> jp = j.Jp(std::vector<double>(pv.begin(), pv.end()));
  const std::vector<double> full = j.Jtu(jp);
  constexpr int kStride = 3;
  for (bool cache : {true, false}) {
    SCOPED_TRACE(cache ? "recorded" : "recomputed");
    std::vector<double> sum(full.size(), 0.0);
    for (int offset = 0; offset < kStride; ++offset) {
      std::vector<double> u = jp;
      for (size_t r = 0; r < u.size(); ++r) {
        if ((r / 4) % kStride != static_cast<size_t>(offset)) u[r] = 0;  // 4 rows a ray
      }
      const std::vector<double> want = j.Jtu(u);
      auto b = Cpu(2, cache);
      LevelProblem level = p.Level();
      level.jtj_ray_stride = kStride;
      b->SetLevel(level, kVectors);
      b->Upload(kX, p.x);
      b->Upload(kP, pv);
      const PassStats lin = b->Linearize(kX, seed, kG, kD, RaySubset{}, RaySubset{kStride, offset});
      EXPECT_EQ(lin.rays, static_cast<int64_t>(p.rays.size()));  // the gradient keeps every ray
      const PassStats m = b->MultiplyJtJ(kP, kOut);
      EXPECT_EQ(m.rays, (RaySubset{kStride, offset}.CountIn(0, p.rays.size())));
      std::vector<float> out(p.shape.ParamCount());
      b->Download(kOut, out);
      ExpectClose(out, want, "J_S^T J_S p");
      for (size_t i = 0; i < sum.size(); ++i) sum[i] += out[i];
      // The reduced system's product keeps its free entries (p zero where held).
      std::vector<float> free(p.shape.ParamCount(), 1.f), held_p = pv;
      for (size_t i = 0; i < free.size(); i += 5) free[i] = 0.f, held_p[i] = 0.f;
      b->Upload(kG, free);
      b->Upload(kP, held_p);
      b->MultiplyJtJ(kP, kOut);
      std::vector<float> before(p.shape.ParamCount()), after(p.shape.ParamCount());
      b->Download(kOut, before);
      b->RestrictJacobian(kG);
      b->MultiplyJtJ(kP, kOut);
      b->Download(kOut, after);
      for (size_t i = 0; i < free.size(); ++i) {
        if (free[i] != 0.f) {
          ASSERT_NEAR(after[i], before[i], 1e-5f * (1 + std::abs(before[i]))) << "entry " << i;
        }
      }
    }
    ExpectClose(std::vector<float>(sum.begin(), sum.end()), full, "the offsets' sum");
  }
  // The record is sized for the recorded rays: about a quarter with every 4th.
  auto b = Cpu(2);
  LevelProblem level = p.Level();
  const int64_t all = b->EstimateMemory(level, kVectors).jacobian_cache;
  level.jtj_ray_stride = 4;
  const int64_t quarter = b->EstimateMemory(level, kVectors).jacobian_cache;
  EXPECT_GT(quarter, all / 5);
  EXPECT_LT(quarter, all * 3 / 10);
}

// What the dense Jacobian says the passes must give: the cost, J^T r, diag(J^T J) and J^T J pv.
struct DenseWant {
  double cost;
  std::vector<double> jtr, diag, jtjp;
  DenseWant(const DenseJacobian& j, const std::vector<float>& pv)
      : cost(j.Cost()), jtr(j.Jtr()), diag(j.Diag()), jtjp(j.Jtu(j.Jp(std::vector<double>(pv.begin(), pv.end())))) {}
};
struct PassOutputs {
  std::vector<float> g, d, out;  // J^T r, diag(J^T J), J^T J pv
};

// Linearize, Cost and MultiplyJtJ of a 2-thread CPU backend (its Jacobian recorded or recomputed)
// on p at p.x with the robust loss of scale `robust` (0: none), each against `want`; returns the
// vectors for checks of their own entries.
// split > 0: the entries before and from `split` are compared on their own scales (the pose
// entries' diagonal dwarfs the volume's).
PassOutputs ExpectPassesMatch(const TinyProblem& p, const DenseWant& want, const std::vector<float>& pv, uint32_t seed,
                              bool cache, float robust = 0.f, int64_t split = 0) {
  auto b = Cpu(2, cache);
  LevelProblem level = p.Level();
  level.residuals.robust_scale = robust;
  b->SetLevel(level, kVectors);
  b->Upload(kX, p.x);
  b->Upload(kP, pv);
  const PassStats s = b->Linearize(kX, seed, kG, kD);
  EXPECT_NEAR(s.cost, want.cost, 1e-5 * want.cost);
  EXPECT_NEAR(b->Cost(kX, seed).cost, want.cost, 1e-5 * want.cost);
  b->MultiplyJtJ(kP, kOut);
  PassOutputs o{std::vector<float>(p.shape.ParamCount()), std::vector<float>(p.shape.ParamCount()),
                std::vector<float>(p.shape.ParamCount())};
  b->Download(kG, o.g);
  b->Download(kD, o.d);
  b->Download(kOut, o.out);
  const auto close = [&](const std::vector<float>& got, const std::vector<double>& w, const char* what) {
    if (split <= 0) return ExpectClose(got, w, what);
    ExpectClose(std::vector<float>(got.begin(), got.begin() + split), std::vector<double>(w.begin(), w.begin() + split),
                what);
    ExpectClose(std::vector<float>(got.begin() + split, got.end()), std::vector<double>(w.begin() + split, w.end()),
                what);
  };
  close(o.g, want.jtr, "J^T r");
  close(o.d, want.diag, "diag(J^T J)");
  close(o.out, want.jtjp, "J^T J p");
  return o;
}

// Per-photo exposures (issue 16): every pass against the dense Jacobian of the transformed
// residuals (gain (1 + gamma) times the volume's partials, H and 1 for the photo's own entries),
// with the Jacobian recorded and recomputed; the exposure entries are exercised (non-zero) and
// the problem differs from the one without exposures.
TEST(CpuBackendTest, ExposuresMatchTheDenseJacobian) {
  TinyProblem p(5);
  const TinyProblem plain = p;
  p.AddExposures(6);
  const uint32_t seed = 19;
  const DenseJacobian j(p, p.x, seed, 0.1);
  const std::vector<float> pv = test::RandomDirection(p.shape, 8);
  const DenseWant want(j, pv);
  for (bool cache : {true, false}) {
    SCOPED_TRACE(cache ? "recorded" : "recomputed");
    const PassOutputs o = ExpectPassesMatch(p, want, pv, seed, cache);
    for (int64_t i = p.shape.ExposureStart(); i < p.shape.ParamCount(); ++i) {
      SCOPED_TRACE(i);
      const bool pad = (i - p.shape.ExposureStart()) % 4 == 3;
      EXPECT_EQ(pad, o.g[i] == 0.f && o.d[i] == 0.f && o.out[i] == 0.f);
      EXPECT_NEAR(o.d[i], want.diag[i], 1e-5 * std::abs(want.diag[i]) + 1e-6);
      EXPECT_NEAR(o.g[i], want.jtr[i], 1e-4 * std::abs(want.jtr[i]) + 1e-5);
      EXPECT_NEAR(o.out[i], want.jtjp[i], 1e-4 * std::abs(want.jtjp[i]) + 1e-4);
    }
  }
  const DenseJacobian without(plain, plain.x, seed, 0.1);
  EXPECT_GT(std::abs(without.Cost() - j.Cost()), 1e-3 * j.Cost());
}

// Pose refinement (pose.h) with exposures and the robust loss: every pass against the dense
// Jacobian whose pose columns are central differences of the residuals, with the Jacobian recorded
// and recomputed; the pose entries are exercised and the corrected poses change the cost.
TEST(CpuBackendTest, PosesMatchTheDenseJacobian) {
  TinyProblem p(7, 4, 2, 3, 7, 6);
  p.AddExposures(6);
  const TinyProblem unposed = [&] {
    TinyProblem q = p;
    q.AddPoses(9, 0.f, 0.f);
    return q;
  }();
  p.AddPoses(9);
  const uint32_t seed = 23;
  for (float robust : {0.f, 0.3f}) {
    SCOPED_TRACE(robust);
    const DenseJacobian j(p, p.x, seed, 0.1, true, true, robust);
    const std::vector<float> pv = test::RandomDirection(p.shape, 8);
    const DenseWant want(j, pv);
    for (bool cache : {true, false}) {
      SCOPED_TRACE(cache ? "recorded" : "recomputed");
      const PassOutputs o = ExpectPassesMatch(p, want, pv, seed, cache, robust, p.shape.PoseStart());
      int exercised = 0;
      for (int64_t i = p.shape.PoseStart(); i < p.shape.ParamCount(); ++i) {
        SCOPED_TRACE(i);
        const bool pad = (i - p.shape.PoseStart()) % kPoseValues == 7;
        EXPECT_EQ(pad, o.g[i] == 0.f && o.d[i] == 0.f && o.out[i] == 0.f);
        EXPECT_NEAR(o.d[i], want.diag[i], 2e-3 * std::abs(want.diag[i]) + 1e-4);
        EXPECT_NEAR(o.g[i], want.jtr[i], 2e-3 * std::abs(want.jtr[i]) + 1e-4);
        EXPECT_NEAR(o.out[i], want.jtjp[i], 2e-3 * std::abs(want.jtjp[i]) + 1e-3);
        exercised += std::abs(want.diag[i]) > 1e-2 ? 1 : 0;
      }
      EXPECT_GE(exercised, kPoseSolved * p.shape.poses - 2);
    }
  }
  const DenseJacobian without(unposed, unposed.x, seed, 0.1);
  const DenseJacobian with(p, p.x, seed, 0.1);
  EXPECT_GT(std::abs(without.Cost() - with.Cost()), 1e-3 * with.Cost());
}

// The robust loss (ResidualSettings::robust_scale): every pass against the dense Jacobian of the
// reweighted system (colour rows and residuals times 1 / sqrt(1 + |r|^2 / c^2)), with exposures,
// recorded and recomputed. The weights vary from ray to ray, and J^T r is the robust cost's
// gradient: central differences of the dense robust cost agree with it.
TEST(CpuBackendTest, RobustLossMatchesTheReweightedDenseJacobian) {
  TinyProblem p(6);
  p.AddExposures(6);
  const uint32_t seed = 23;
  const float c = 0.1f;
  const DenseJacobian j(p, p.x, seed, 0.1, true, true, c);
  const auto [lo, hi] = std::minmax_element(j.row_scales.begin(), j.row_scales.end());
  EXPECT_LT(*lo, 0.5) << "some rays are down-weighted";
  EXPECT_GT(*hi - *lo, 0.3) << "by different amounts";
  const std::vector<float> pv = test::RandomDirection(p.shape, 9);
  const DenseWant want(j, pv);
  for (bool cache : {true, false}) {
    SCOPED_TRACE(cache ? "recorded" : "recomputed");
    ExpectPassesMatch(p, want, pv, seed, cache, c);
  }
  const DenseJacobian plain(p, p.x, seed, 0.1);
  EXPECT_LT(j.Cost(), 0.9 * plain.Cost());
  // The gradient: central differences of the robust cost at the parameters with the largest entries.
  const std::vector<double> g = j.Jtr();
  std::vector<int64_t> order(g.size());
  std::iota(order.begin(), order.end(), 0);
  std::partial_sort(order.begin(), order.begin() + 20, order.end(),
                    [&](int64_t a, int64_t b) { return std::abs(g[a]) > std::abs(g[b]); });
  std::vector<double> x(p.x.begin(), p.x.end());
  for (int k = 0; k < 20; ++k) {
    const int64_t i = order[k];
    const double h = 1e-5;
    x[i] += h;
    const double up = DenseJacobian(p, x, seed, 0.1, true, true, c).Cost();
    x[i] -= 2 * h;
    const double down = DenseJacobian(p, x, seed, 0.1, true, true, c).Cost();
    x[i] += h;
    EXPECT_NEAR((up - down) / (2 * h), g[i], 1e-4 * std::abs(g[i]) + 1e-7) << "parameter " << i;
  }
}

// View-dependent colour (issue 16, --sh-degree): spherical harmonics of degree 1 and 2 (the
// second with exposures too) against the dense Jacobian in every pass, recorded and recomputed.
// Degree 1 again with half the grid empty (density 0 at its bound): there the samples' colour
// partial dc is 0, the passes skip their bands (jacobian.h ScatterSh), and Forward still
// records their colour for the density's partial.
TEST(CpuBackendTest, SphericalHarmonicsMatchTheDenseJacobian) {
  for (const int variant : {1, 2, -1}) {
    const int degree = std::abs(variant);
    SCOPED_TRACE(variant);
    TinyProblem p(7);
    if (variant < 0) {
      for (int64_t cell = 0; cell < p.shape.StoredCells(); ++cell) {
        if (cell % p.shape.n < p.shape.n / 2) p.x[GridParam(cell, 3)] = 0.f;
      }
    }
    const TinyProblem plain = p;
    p.AddSh(degree, 8);
    if (degree == 2) p.AddExposures(9);
    const uint32_t seed = 23;
    const DenseJacobian j(p, p.x, seed, 0.1);
    const std::vector<float> pv = test::RandomDirection(p.shape, 10);
    const DenseWant want(j, pv);
    for (bool cache : {true, false}) {
      SCOPED_TRACE(cache ? "recorded" : "recomputed");
      const PassOutputs o = ExpectPassesMatch(p, want, pv, seed, cache);
      // The coefficients' own entries, on their own scale, and some of them exercised.
      int nonzero = 0;
      for (int64_t i = p.shape.ShStart(); i < p.shape.ExposureStart(); ++i) {
        EXPECT_NEAR(o.g[i], want.jtr[i], 1e-4 * std::abs(want.jtr[i]) + 1e-5) << i;
        EXPECT_NEAR(o.d[i], want.diag[i], 1e-4 * std::abs(want.diag[i]) + 1e-6) << i;
        EXPECT_NEAR(o.out[i], want.jtjp[i], 1e-4 * std::abs(want.jtjp[i]) + 1e-4) << i;
        nonzero += std::abs(want.jtr[i]) > 1e-3;
      }
      EXPECT_GT(nonzero, 50);
    }
    const DenseJacobian without(plain, plain.x, seed, 0.1);
    EXPECT_GT(std::abs(without.Cost() - j.Cost()), 1e-3 * j.Cost());
  }
}

// A sparse level (3 of 8 bricks stored) against the dense level whose other bricks are empty:
// the same cost, and on the stored cells the same J^T r, diag(J^T J), J^T J p and renders, with
// fewer samples marched.
TEST(CpuBackendTest, SparseLevelEqualsTheDenseOneWhereTheBricksAreEmpty) {
  const TinyProblem p(5, 16, 4, 6, 24, 18);
  const test::SparseVersion s(p, {1, 0, 0, 1, 0, 1, 0, 0});
  auto sparse = Cpu(2), dense = Cpu(2);
  sparse->SetLevel(s.level, kVectors);
  sparse->Upload(kX, s.x);
  LevelProblem dense_level = s.level;
  dense_level.shape = p.shape;
  dense->SetLevel(dense_level, kVectors);
  dense->Upload(kX, s.dense_x);
  const auto get = [](Backend* b, VecId v) {
    std::vector<float> out(b->level().shape.ParamCount());
    b->Download(v, out);
    return out;
  };
  const PassStats a = sparse->Linearize(kX, 9, kG, kD), b = dense->Linearize(kX, 9, kG, kD);
  EXPECT_NEAR(a.cost, b.cost, 1e-6 * b.cost);
  EXPECT_EQ(a.rays, b.rays);
  EXPECT_LT(a.samples, b.samples * 3 / 4) << "the march skips the empty bricks";
  test::ExpectAllClose(get(sparse.get(), kG), s.Stored(get(dense.get(), kG)), 1e-5, 1e-5, "J^T r");
  test::ExpectAllClose(get(sparse.get(), kD), s.Stored(get(dense.get(), kD)), 1e-5, 1e-5, "diag(J^T J)");
  const std::vector<float> pv = test::RandomDirection(s.level.shape, 2);
  sparse->Upload(kP, pv);
  dense->Upload(kP, s.Dense(pv));
  sparse->MultiplyJtJ(kP, kOut);
  dense->MultiplyJtJ(kP, kOut);
  test::ExpectAllClose(get(sparse.get(), kOut), s.Stored(get(dense.get(), kOut)), 1e-5, 1e-5, "J^T J p");
  EXPECT_NEAR(sparse->Cost(kX, 4).cost, dense->Cost(kX, 4).cost, 1e-6 * dense->Cost(kX, 4).cost);
  const RenderOutput ra = sparse->Render(kX, p.rays.cameras[0], 24, 18, 0.f);
  const RenderOutput rb = dense->Render(kX, p.rays.cameras[0], 24, 18, 0.f);
  test::ExpectAllClose(ra.colour, rb.colour, 1e-6, 1e-6, "render");
  test::ExpectAllClose(ra.opacity, rb.opacity, 1e-6, 1e-6, "render opacity");
}

TEST(CpuBackendTest, CostPassAgreesWithLinearizeAndSubsets) {
  const TinyProblem p(4, 4, 2, 4, 7, 6);
  auto b = Cpu(2);
  b->SetLevel(p.Level(), kVectors);
  b->Upload(kX, p.x);
  const PassStats lin = b->Linearize(kX, 9, kG, kD);
  const PassStats all = b->Cost(kX, 9);
  EXPECT_DOUBLE_EQ(all.cost, lin.cost);  // same rays, jitter and block order
  EXPECT_EQ(all.samples, lin.samples);
  double parts = 0;
  int64_t rays = 0;
  for (int off = 0; off < 3; ++off) {
    const PassStats s = b->Cost(kX, 9, RaySubset{3, off});
    parts += s.cost;
    rays += s.rays;
  }
  EXPECT_EQ(rays, p.rays.size());
  EXPECT_NEAR(parts, all.cost, 1e-9 * all.cost);
  EXPECT_NE(b->Cost(kX, 10).cost, all.cost);  // another seed, other jitter
}

// Linearize's subset cost is the line search's starting cost: exactly what Cost sums on that
// subset, with and without the diagonal, over several blocks of rays (2592 rays, 3 blocks).
TEST(CpuBackendTest, LinearizeSumsItsSubsetAsCostDoes) {
  const TinyProblem p(5, 4, 2, 6, 24, 18);
  ASSERT_GT(p.rays.size(), 2048);
  auto b = Cpu(2);
  b->SetLevel(p.Level(), kVectors);
  b->Upload(kX, p.x);
  for (const VecId diag : {VecId{kD}, kNoVector}) {
    const PassStats whole = b->Linearize(kX, 9, kG, diag);
    EXPECT_EQ(whole.subset_cost, whole.cost);
    for (int off = 0; off < 4; ++off) {
      const PassStats lin = b->Linearize(kX, 9, kG, diag, RaySubset{4, off});
      const PassStats cost = b->Cost(kX, 9, RaySubset{4, off});
      EXPECT_EQ(lin.subset_cost, cost.cost) << "offset " << off;
      EXPECT_LT(lin.subset_cost, 0.5 * lin.cost);
    }
  }
}

TEST(CpuBackendTest, OneAndTwoThreadsAgree) {
  const TinyProblem p(5, 8, 4, 6, 16, 12);
  std::vector<float> g1(p.shape.ParamCount()), g2(p.shape.ParamCount());
  double c1 = 0, c2 = 0;
  for (int threads : {1, 2}) {
    auto b = Cpu(threads);
    b->SetLevel(p.Level(), kVectors);
    b->Upload(kX, p.x);
    const double c = b->Linearize(kX, 3, kG, kD).cost;
    (threads == 1 ? c1 : c2) = c;
    b->Download(kG, threads == 1 ? g1 : g2);
  }
  EXPECT_EQ(c1, c2);  // per-block sums in block order: bit-identical
  float worst = 0, scale = 0;
  for (size_t i = 0; i < g1.size(); ++i) {
    worst = std::max(worst, std::abs(g1[i] - g2[i]));
    scale = std::max(scale, std::abs(g1[i]));
  }
  EXPECT_LE(worst, 1e-5f * scale);
}

TEST(CpuBackendTest, VectorOperations) {
  const TinyProblem p(6);
  auto b = Cpu(2);
  b->SetLevel(p.Level(), kVectors);
  const int64_t n = p.shape.ParamCount();
  std::vector<float> a(n), c(n);
  for (int64_t i = 0; i < n; ++i) {
    a[i] = 0.5f + 0.001f * static_cast<float>(i % 97);
    c[i] = -1.0f + 0.002f * static_cast<float>(i % 13);
  }
  b->Upload(kX, a);
  b->Upload(kG, c);
  double dot = 0;
  for (int64_t i = 0; i < n; ++i) dot += static_cast<double>(a[i]) * c[i];
  EXPECT_NEAR(b->Dot(kX, kG), dot, 1e-9 * std::abs(dot));
  b->Copy(kP, kX);
  b->Axpy(kP, 2.0, kG);  // a + 2c
  b->Xpby(kP, kG, 0.5);  // c + 0.5 (a + 2c) = 2c + 0.5a
  std::vector<float> out(n);
  b->Download(kP, out);
  for (int64_t i = 0; i < n; i += 101) EXPECT_NEAR(out[i], 2 * c[i] + 0.5f * a[i], 1e-5f);
  b->DivideClamped(kOut, kG, kX, 0.6f);
  b->Download(kOut, out);
  for (int64_t i = 0; i < n; i += 101) EXPECT_NEAR(out[i], c[i] / std::max(a[i], 0.6f), 1e-6f);
  EXPECT_NEAR(b->MaxAbs(kG), 1.0, 1e-6);
  b->Fill(kP, -2.f);
  b->Project(kP);
  b->Download(kP, out);
  EXPECT_EQ(out[3], 0.f);                         // grid sigma >= 0
  EXPECT_EQ(out[0], 0.f);                         // colour >= 0
  EXPECT_EQ(out[p.shape.GridParamCount() + 3], 0.f);  // shell opacity >= 0
  b->Fill(kP, 7.f);
  b->Project(kP);
  b->Download(kP, out);
  EXPECT_EQ(out[3], 7.f);  // sigma has no upper bound
  EXPECT_EQ(out[2], 1.f);
  EXPECT_EQ(out[p.shape.GridParamCount() + 3], 1.f);
}

TEST(CpuBackendTest, ARenderOnlyLevelRendersAsATrainingLevelDoes) {
  // SetLevel without rays (checkpoint rendering): the same image as with the training rays, and
  // the ray passes see none.
  const TinyProblem p(3);
  auto train = Cpu(2), render = Cpu(2);
  train->SetLevel(p.Level(), 1);
  LevelProblem only = p.Level();
  only.rays = nullptr;
  render->SetLevel(only, 1);
  EXPECT_EQ(render->kind(), BackendKind::kCpu);
  train->Upload(0, p.x);
  render->Upload(0, p.x);
  const RenderOutput a = train->Render(0, p.rays.cameras[0], 6, 5, 0.f);
  const RenderOutput b = render->Render(0, p.rays.cameras[0], 6, 5, 0.f);
  EXPECT_EQ(a.colour, b.colour);
  EXPECT_EQ(a.opacity, b.opacity);
  EXPECT_EQ(render->Cost(0, 1).rays, 0);
}

TEST(CpuBackendTest, RenderSeesTheShellsThroughAnEmptyBox) {
  TinyProblem p(7);
  // Empty box: every pixel is the shells' colour, whatever the opacity rule.
  for (int64_t i = 3; i < p.shape.GridParamCount(); i += 4) p.x[i] = 0;
  auto b = Cpu(2);
  b->SetLevel(p.Level(), 1);
  b->Upload(0, p.x);
  const RenderOutput with_rule = b->Render(0, p.rays.cameras[0], 6, 5, 0.7f);
  const RenderOutput without = b->Render(0, p.rays.cameras[0], 6, 5, 0.f);
  for (size_t i = 0; i < with_rule.colour.size(); ++i) EXPECT_FLOAT_EQ(with_rule.colour[i], without.colour[i]);
  for (float o : with_rule.opacity) EXPECT_EQ(o, 0.f);
  // A dense box is opaque: the rule keeps it.
  for (int64_t i = 3; i < p.shape.GridParamCount(); i += 4) p.x[i] = 50;
  b->Upload(0, p.x);
  const RenderOutput dense = b->Render(0, p.rays.cameras[0], 6, 5, 0.7f);
  int opaque = 0;
  for (float o : dense.opacity) opaque += o > 0.99f;
  EXPECT_GT(opaque, 10);
  // Faint density: the rule hides it, without the rule it shows.
  for (int64_t i = 3; i < p.shape.GridParamCount(); i += 4) p.x[i] = 0.1f;
  b->Upload(0, p.x);
  const RenderOutput faint_rule = b->Render(0, p.rays.cameras[0], 6, 5, 0.7f);
  const RenderOutput faint = b->Render(0, p.rays.cameras[0], 6, 5, 0.f);
  double diff_rule = 0, diff = 0;
  for (size_t i = 0; i < faint.colour.size(); ++i) {
    diff_rule += std::abs(faint_rule.colour[i] - without.colour[i]);
    diff += std::abs(faint.colour[i] - without.colour[i]);
  }
  EXPECT_LT(diff_rule, 1e-5);
  EXPECT_GT(diff, 0.1);
}

TEST(CpuBackendTest, SetLevelRefusesWhatDoesNotFit) {
  const TinyProblem p(8);
  CpuBackendOptions o;
  o.max_memory = 1000;  // bytes
  auto b = MakeCpuBackend(o);
  try {
    b->SetLevel(p.Level(), kVectors);
    FAIL() << "expected ResourceError";
  } catch (const ResourceError& e) {
    EXPECT_NE(std::string(e.what()).find("MiB"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--levels"), std::string::npos) << e.what();
  }
}

TEST(CpuBackendTest, AbsurdThreadCountsAreRefusedAndAFailedSetLevelLeavesAUsableBackend) {
  // TBB crashed destroying an arena of 100000 threads (perf render -j 100000: SIGSEGV).
  CpuBackendOptions o;
  o.threads = 100000;
  EXPECT_THROW(MakeCpuBackend(o), InputError);
  o.threads = -3;
  EXPECT_THROW(MakeCpuBackend(o), InputError);
  // A level that does not fit is refused before allocating; the backend then takes one that
  // fits, and is destroyed cleanly.
  const TinyProblem p(1);
  o.threads = 2;
  o.max_memory = 1024;
  auto b = MakeCpuBackend(o);
  EXPECT_THROW(b->SetLevel(p.Level(0.1f, true), kVectors), ResourceError);
  b = Cpu(2);
  b->SetLevel(p.Level(0.1f, true), kVectors);
  b->Upload(kX, p.x);
  EXPECT_GT(b->Cost(kX, 1).cost, 0);
}

}  // namespace
}  // namespace perf::recon
