// CUDA backend against the CPU backend (STYLE.md "Tests": CUDA against CPU on the same rays):
// the same problem, seed and rays on both, compared pass by pass (cost, J^T r, diag(J^T J),
// J^T J p, the cost on a subset, renders, the vector operations) and over short solves (GN and
// Adam), plus one pass-level case at the benchmark's settings (~1e5 rays, early termination,
// fixed shells, alpha). Skips with "no CUDA device: ..." where there is none (CI), and fails
// instead with PERF_REQUIRE_GPU=1 (require_gpu.h; RequireGpuTest checks both ways on any
// machine); label gpu.
//
// Tolerances. Both backends run the same float code, but not the same float operations:
//   - scatters are float atomics on the GPU (any order) and per-thread sums on the CPU, so every
//     entry of g, diag and J^T J p is the same sum in another order; an entry sums at most a few
//     hundred terms here, so the reordering moves it by ~k eps sum|terms| (eps = 6e-8), well
//     under 1e-5 of the largest entry;
//   - nvcc contracts a * b + c into FMAs and its expf differs from glibc's by ~1-2 ulp; these
//     perturb every partial by ~1e-7 relative, again far below the bound;
// so entries must agree to 1e-4 of the largest entry plus 1e-4 of their own size (the CPU test
// against the double reference uses 2e-4), and costs (double sums of float residuals) to 1e-5.
// Targets are quantised to k / 255 first, so the GPU's 8-bit training colours are exact.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <utility>

#include "common/errors.h"
#include "common/subprocess.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/backends/cuda_backend.h"
#include "recon_cuda/backends/cuda_kernels.h"
#include "recon_cuda/backends/device_record_plan.h"
#include "recon_cuda/backends/distributed_backend.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/data/volume.h"
#include "recon_cuda/solve/hierarchy.h"
#include "recon_cuda/solve/solver.h"
#include "tests/recon/recon_test_util.h"
#include "tests/recon/require_gpu.h"
#include "tests/recon/synthetic_scene.h"
#include "tests/recon/thread_group.h"

namespace perf::recon {
namespace {

using test::TinyProblem;

// Targets as 8-bit photos have them (the CUDA backend stores colours in 8 bits).
// The device stores colours and alphas in 8 bits: quantised, both backends see the same values.
void QuantiseColours(RaySet* rays) {
  for (float& c : rays->colours) c = std::round(std::clamp(c, 0.f, 1.f) * 255.f) / 255.f;
  for (float& a : rays->alphas) a = std::round(std::clamp(a, 0.f, 1.f) * 255.f) / 255.f;
}

void ExpectClose(const std::vector<float>& gpu, const std::vector<float>& cpu, const char* what,
                 double exercised = 0.1) {
  test::ExpectAllClose(gpu, cpu, 1e-4, 1e-4, what, exercised);
}

void ExpectStatsClose(const PassStats& gpu, const PassStats& cpu, const char* what) {
  EXPECT_NEAR(gpu.cost, cpu.cost, 1e-5 * cpu.cost) << what;
  EXPECT_NEAR(gpu.colour_sse, cpu.colour_sse, 1e-5 * cpu.colour_sse) << what;
  EXPECT_EQ(gpu.rays, cpu.rays) << what;
  // A march's length is a ceil of float values: an FMA may tip one by a sample.
  EXPECT_NEAR(static_cast<double>(gpu.samples), static_cast<double>(cpu.samples), 1e-3 * cpu.samples) << what;
}

enum : VecId { kX, kG, kD, kP, kOut, kVectors };

class GpuParityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string reason;
    PERF_SKIP_OR_FAIL_WITHOUT_GPU(ProbeCudaDevice(nullptr, &reason), reason);
    CudaBackendOptions g;
    g.record_jacobian = false;  // J^T J p recomputed from x, exactly as the CPU's exact record has it
    gpu = MakeCudaBackend(g);
    CpuBackendOptions o;
    o.threads = 2;
    o.compact_jacobian = false;  // the exact record: the parity tolerances hold the CPU's math, not its storage
    cpu = MakeCpuBackend(o);
  }
  // Both backends at the problem's level with its x in kX.
  void SetLevel(const LevelProblem& level, const std::vector<float>& x, int vectors = kVectors) {
    for (Backend* b : {cpu.get(), gpu.get()}) {
      b->SetLevel(level, vectors);
      b->Upload(kX, x);
    }
  }
  std::vector<float> Get(Backend* b, VecId v) {
    std::vector<float> out(b->level().shape.ParamCount());
    b->Download(v, out);
    return out;
  }

  std::unique_ptr<Backend> gpu, cpu;
};

// A problem with a few thousand rays and ~2.5k parameters, so most entries are reached.
TinyProblem Problem(uint32_t seed) {
  TinyProblem p(seed, 8, 4, 6, 24, 18);
  QuantiseColours(&p.rays);
  return p;
}

TEST_F(GpuParityTest, DescribesTheDevice) { EXPECT_EQ(gpu->Describe().rfind("cuda (", 0), 0u) << gpu->Describe(); }

TEST_F(GpuParityTest, LinearizeCostGradientAndDiagonal) {
  const TinyProblem p = Problem(1);
  SetLevel(p.Level(), p.x);
  for (bool with_diag : {true, false}) {
    const PassStats c = cpu->Linearize(kX, 77, kG, with_diag ? kD : kNoVector);
    const PassStats g = gpu->Linearize(kX, 77, kG, with_diag ? kD : kNoVector);
    ExpectStatsClose(g, c, "linearize");
    ExpectClose(Get(gpu.get(), kG), Get(cpu.get(), kG), with_diag ? "J^T r (GN)" : "J^T r (Adam)");
    if (with_diag) ExpectClose(Get(gpu.get(), kD), Get(cpu.get(), kD), "diag(J^T J)");
  }
  // The cost is summed in a fixed order: the same on every run.
  EXPECT_EQ(gpu->Linearize(kX, 77, kG, kD).cost, gpu->Linearize(kX, 77, kG, kD).cost);
}

TEST_F(GpuParityTest, AlphaResidual) {
  TinyProblem p(9, 8, 4, 6, 24, 18);
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (int64_t i = 0; i < p.rays.size(); ++i) p.rays.alphas.push_back(i % 4 == 0 ? 0.f : u(rng));
  QuantiseColours(&p.rays);
  SetLevel(p.Level(), p.x);
  const PassStats c = cpu->Linearize(kX, 5, kG, kD);
  const PassStats g = gpu->Linearize(kX, 5, kG, kD);
  ExpectStatsClose(g, c, "linearize with alpha");
  ExpectClose(Get(gpu.get(), kG), Get(cpu.get(), kG), "J^T r with alpha");
  ExpectClose(Get(gpu.get(), kD), Get(cpu.get(), kD), "diag with alpha");
  std::vector<float> pv(p.shape.ParamCount());
  for (float& v : pv) v = u(rng) - 0.5f;
  for (Backend* b : {cpu.get(), gpu.get()}) b->Upload(kP, pv);
  cpu->MultiplyJtJ(kP, kOut);
  gpu->MultiplyJtJ(kP, kOut);
  ExpectClose(Get(gpu.get(), kOut), Get(cpu.get(), kOut), "J^T J p with alpha");
  ExpectStatsClose(gpu->Cost(kX, 5), cpu->Cost(kX, 5), "cost with alpha");
}

TEST_F(GpuParityTest, JtJpAtTheLinearisationPoint) {
  const TinyProblem p = Problem(3);
  SetLevel(p.Level(), p.x);
  std::mt19937 rng(4);
  std::normal_distribution<float> n;
  std::vector<float> pv(p.shape.ParamCount());
  for (float& v : pv) v = n(rng);
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->Upload(kP, pv);
    b->Linearize(kX, 11, kG, kD);
  }
  const PassStats c = cpu->MultiplyJtJ(kP, kOut);
  const PassStats g = gpu->MultiplyJtJ(kP, kOut);
  EXPECT_EQ(g.rays, c.rays);
  EXPECT_NEAR(static_cast<double>(g.samples), static_cast<double>(c.samples), 1e-3 * c.samples);
  ExpectClose(Get(gpu.get(), kOut), Get(cpu.get(), kOut), "J^T J p");
  // Subsampled Gauss-Newton (SolverOptions::jtj_ray_stride): every 3rd ray from offset 2.
  for (Backend* b : {cpu.get(), gpu.get()}) b->Linearize(kX, 11, kG, kD, RaySubset{}, RaySubset{3, 2});
  const PassStats cs = cpu->MultiplyJtJ(kP, kOut);
  const PassStats gs = gpu->MultiplyJtJ(kP, kOut);
  EXPECT_EQ(gs.rays, cs.rays);
  EXPECT_LT(cs.rays, c.rays / 2);
  ExpectClose(Get(gpu.get(), kOut), Get(cpu.get(), kOut), "J^T J p on every 3rd ray");
}

// Per-photo exposures (issue 16): every pass with six photos' transforms. A photo's 432 rays fill
// 13.5 warps, so the device's warp sums of the exposure entries (cuda_passes.cu WarpAddExposure)
// meet both warps of one photo and warps shared by two.
TEST_F(GpuParityTest, ExposuresInEveryPass) {
  // With spherical harmonics (issue 16, --sh-degree), with the robust loss (--robust), and with
  // the photos' poses refined (pose.h; their entries follow the exposures').
  struct Case {
    int degree;
    float robust;
    bool poses;
  };
  for (const Case& k : {Case{0, 0.f, false}, Case{2, 0.f, false}, Case{0, 0.1f, false}, Case{1, 0.f, true}}) {
  const int degree = k.degree;
  const float robust = k.robust;
  SCOPED_TRACE(StrCat("degree ", degree, ", robust ", robust, k.poses ? ", poses" : ""));
  TinyProblem p = Problem(47);
  if (degree > 0) p.AddSh(degree, 50);
  p.AddExposures(48);
  if (k.poses) p.AddPoses(51);
  LevelProblem level = p.Level();
  level.residuals.robust_scale = robust;
  SetLevel(level, p.x);
  const int64_t e = p.shape.ExposureStart(), n = p.shape.ParamCount();
  // The volume's entries on their own scale when the poses' (far larger) follow.
  const auto head = [&](Backend* b, VecId v) {
    const std::vector<float> all = Get(b, v);
    return std::vector<float>(all.begin(), all.begin() + (k.poses ? e : n));
  };
  const auto tail = [&](Backend* b, VecId v) {
    const std::vector<float> all = Get(b, v);
    return std::vector<float>(all.begin() + e, all.end());
  };
  const auto expect_tail = [&](VecId v, const char* what) {
    const std::vector<float> c = tail(cpu.get(), v), g = tail(gpu.get(), v);
    const double tol = k.poses ? 1e-3 : 1e-4;
    for (int64_t i = 0; i < n - e; ++i) EXPECT_NEAR(g[i], c[i], tol * (1 + std::abs(c[i]))) << what << " entry " << i;
  };
  for (bool with_diag : {true, false}) {
    const PassStats c = cpu->Linearize(kX, 13, kG, with_diag ? kD : kNoVector);
    const PassStats g = gpu->Linearize(kX, 13, kG, with_diag ? kD : kNoVector);
    ExpectStatsClose(g, c, "linearize with exposures");
    ExpectClose(head(gpu.get(), kG), head(cpu.get(), kG), "J^T r with exposures");
    expect_tail(kG, "J^T r's exposures");
    if (with_diag) {
      // At degree 2 most of a cell's 28 diagonal entries are its bands' squares, below 1e-3 of the
      // largest (the first GPU run: 721 of 15150 clearly non-zero), so 3 % must be.
      ExpectClose(head(gpu.get(), kD), head(cpu.get(), kD), "diag with exposures", degree >= 2 ? 0.03 : 0.1);
      expect_tail(kD, "diag's exposures");
      EXPECT_NEAR(gpu->MaxAbsVolume(kD), cpu->MaxAbsVolume(kD), 1e-5 * cpu->MaxAbsVolume(kD));
      EXPECT_LT(cpu->MaxAbsVolume(kD), cpu->MaxAbs(kD));  // a photo's entries outweigh any cell's
    }
  }
  const std::vector<float> pv = test::RandomDirection(p.shape, 49);
  for (Backend* b : {cpu.get(), gpu.get()}) b->Upload(kP, pv);
  cpu->MultiplyJtJ(kP, kOut);
  gpu->MultiplyJtJ(kP, kOut);
  ExpectClose(head(gpu.get(), kOut), head(cpu.get(), kOut), "J^T J p with exposures");
  expect_tail(kOut, "J^T J p's exposures");
  ExpectStatsClose(gpu->Cost(kX, 13), cpu->Cost(kX, 13), "cost with exposures");
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->Copy(kOut, kX);
    b->Axpy(kOut, 3.0, kP);  // far outside the exposures' range
    b->Project(kOut);
  }
  // The clamped entries exactly; the others (x + 3 p) to rounding: the device fuses the multiply-add.
  const std::vector<float> projected_cpu = tail(cpu.get(), kOut), projected_gpu = tail(gpu.get(), kOut);
  ASSERT_EQ(projected_gpu.size(), projected_cpu.size());
  for (size_t i = 0; i < projected_cpu.size(); ++i) {
    EXPECT_NEAR(projected_gpu[i], projected_cpu[i], 1e-6 * (1 + std::abs(projected_cpu[i]))) << "projected entry " << i;
  }
  }
}

// RestrictJacobian: the CPU drops recorded samples, the GPU skips them on the fly; on the free
// entries both equal the unrestricted product (half the box empty, its densities held).
TEST_F(GpuParityTest, RestrictedJtJpOnTheFreeEntries) {
  TinyProblem p = Problem(6);
  const int n = p.shape.n;
  enum : VecId { kFree = kVectors };
  std::vector<float> free(p.shape.ParamCount(), 1.f), pv(p.shape.ParamCount());
  std::mt19937 rng(6);
  std::normal_distribution<float> normal;
  for (float& v : pv) v = normal(rng);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n / 2; ++i) {
        const int64_t sigma = GridParam(GridCell(n, i, j, k), 3);
        p.x[sigma] = free[sigma] = pv[sigma] = 0.f;
      }
  SetLevel(p.Level(), p.x, kVectors + 1);
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->Upload(kP, pv);
    b->Upload(kFree, free);
    b->Linearize(kX, 13, kG, kD);
  }
  cpu->MultiplyJtJ(kP, kOut);
  std::vector<float> want = Get(cpu.get(), kOut);
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->RestrictJacobian(kFree);
    b->MultiplyJtJ(kP, kOut);
    b->Multiply(kOut, kFree);
  }
  for (size_t i = 0; i < want.size(); ++i) want[i] *= free[i];
  ExpectClose(Get(gpu.get(), kOut), want, "restricted J^T J p (GPU)");
  ExpectClose(Get(cpu.get(), kOut), want, "restricted J^T J p (CPU)");
}

TEST_F(GpuParityTest, CostOnSubsetsAndWithEarlyTermination) {
  TinyProblem p = Problem(4);
  LevelProblem level = p.Level();
  SetLevel(level, p.x);
  for (RaySubset s : {RaySubset{1, 0}, RaySubset{4, 0}, RaySubset{3, 2}}) {
    ExpectStatsClose(gpu->Cost(kX, 9, s), cpu->Cost(kX, 9, s), "cost");
    const double subset = cpu->Cost(kX, 9, s).cost;
    EXPECT_NEAR(gpu->Linearize(kX, 9, kG, kD, s).subset_cost, subset, 1e-5 * subset) << "Linearize's subset cost";
  }
  // The default early termination: a ray whose transmittance crosses the threshold within float
  // rounding of it may stop one sample apart on the two backends (a change below 1e-4 of its
  // colour), so the cost agrees to 1e-4 here.
  level.residuals = ResidualSettings{};
  SetLevel(level, p.x);
  const PassStats c = cpu->Cost(kX, 5), g = gpu->Cost(kX, 5);
  EXPECT_NEAR(g.cost, c.cost, 1e-4 * c.cost);
  EXPECT_EQ(g.rays, c.rays);
}

TEST_F(GpuParityTest, Render) {
  const TinyProblem p = Problem(7);
  SetLevel(p.Level(), p.x, 1);
  for (float rule : {0.f, 0.7f}) {
    const RenderOutput c = cpu->Render(kX, p.rays.cameras[1], 24, 18, rule);
    const RenderOutput g = gpu->Render(kX, p.rays.cameras[1], 24, 18, rule);
    ASSERT_EQ(g.colour.size(), c.colour.size());
    int flipped = 0;  // pixels whose box opacity is within rounding of the rule's threshold
    for (size_t i = 0; i < c.opacity.size(); ++i) {
      EXPECT_NEAR(g.opacity[i], c.opacity[i], 1e-5) << i;
      if (rule > 0 && std::abs(c.opacity[i] - rule) < 1e-5f) {
        ++flipped;
        continue;
      }
      for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(g.colour[3 * i + ch], c.colour[3 * i + ch], 1e-5) << i;
    }
    EXPECT_LE(flipped, 1);
  }
  // Larger than one of the backend's render bands (2^20 pixels): drawn in two bands.
  const int w = 1100, h = 1000;
  const RenderOutput c = cpu->Render(kX, p.rays.cameras[1], w, h, 0.f);
  const RenderOutput g = gpu->Render(kX, p.rays.cameras[1], w, h, 0.f);
  ASSERT_EQ(g.colour.size(), c.colour.size());
  ASSERT_EQ(g.opacity.size(), c.opacity.size());
  double worst = 0;
  size_t at = 0;
  for (size_t i = 0; i < c.colour.size(); ++i) {
    const double d = std::abs(g.colour[i] - c.colour[i]) + std::abs(g.opacity[i / 3] - c.opacity[i / 3]);
    if (d > worst) worst = d, at = i / 3;
  }
  EXPECT_LT(worst, 2e-5) << "pixel " << at % w << ", " << at / w;
}

TEST_F(GpuParityTest, VectorOperations) {
  const TinyProblem p = Problem(6);
  SetLevel(p.Level(), p.x);
  const int64_t n = p.shape.ParamCount();
  std::mt19937 rng(5);
  std::normal_distribution<float> g;
  std::vector<float> a(n), c(n), d(n);
  for (int64_t i = 0; i < n; ++i) {
    a[i] = g(rng);
    c[i] = g(rng);
    d[i] = std::abs(g(rng));
  }
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->Upload(kG, a);
    b->Upload(kP, c);
    b->Upload(kD, d);
  }
  // Double sums of float products: the orders differ, the values to ~1e-15 relative.
  EXPECT_NEAR(gpu->Dot(kG, kP), cpu->Dot(kG, kP), 1e-12 * n);
  EXPECT_EQ(gpu->Dot(kG, kP), gpu->Dot(kG, kP));
  EXPECT_EQ(gpu->MaxAbs(kG), cpu->MaxAbs(kG));
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->Copy(kOut, kG);
    b->Axpy(kOut, 0.3, kP);
    b->Xpby(kOut, kP, -0.7);
    b->AxpyDiag(kOut, 0.1, kD, kG);
    b->DivideClamped(kOut, kOut, kD, 0.25f);
  }
  // Element-wise float operations: the same operations (FMA contraction aside), to a few ulp.
  ExpectClose(Get(gpu.get(), kOut), Get(cpu.get(), kOut), "vector operations");
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->Fill(kOut, -0.5f);
    b->Project(kOut);
  }
  EXPECT_EQ(Get(gpu.get(), kOut), Get(cpu.get(), kOut));
  // The active set: x with a third of its entries at 0 or 1, g of both signs; exact on both.
  std::vector<float> xb = p.x;
  for (int64_t i = 0; i < n; i += 3) xb[i] = (i / 3) % 2 ? 1.f : 0.f;
  for (const bool fixed_shells : {false, true}) {
    LevelProblem level = p.Level();
    level.fixed_shells = fixed_shells;
    SetLevel(level, xb);
    for (const bool bounds : {false, true}) {
      for (Backend* b : {cpu.get(), gpu.get()}) {
        b->Upload(kG, a);
        b->HoldParameters(kX, kG, kOut, bounds);
        b->Multiply(kG, kOut);
      }
      EXPECT_EQ(Get(gpu.get(), kOut), Get(cpu.get(), kOut));
      EXPECT_EQ(Get(gpu.get(), kG), Get(cpu.get(), kG));
    }
  }
  SetLevel(p.Level(), p.x);
  for (Backend* b : {cpu.get(), gpu.get()}) b->Upload(kG, a);
  AdamSettings s;
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->Fill(kD, 0.f);
    b->Fill(kOut, 0.f);
    for (int t = 1; t <= 3; ++t) b->AdamStep(kX, kG, kD, kOut, s, t);
  }
  ExpectClose(Get(gpu.get(), kX), Get(cpu.get(), kX), "Adam");
}

TEST_F(GpuParityTest, ShortSolvesReachTheSameCost) {
  // 20 views of 24 x 24 of the synthetic scene (synthetic_scene.h), a 16^3 grid from the random
  // start. Each pass agrees to ~1e-6, but a solve makes discrete choices (CG's exit ratio, the
  // line search's step) that such differences can tip, after which the paths differ slightly:
  // final costs within 3 %, and both far below the start.
  const test::SyntheticScene scene(16, 8, 20, 24, 5);
  RaySet rays = MakeRaySet(scene.train);
  QuantiseColours(&rays);
  const VolumeShape shape{16, 8, 2};
  const std::vector<float> x0 = InitialParams(shape, scene.geometry, InitOptions{});
  for (SolverType type : {SolverType::kGaussNewton, SolverType::kAdam}) {
    SolverOptions so;
    so.type = type;
    so.max_iterations = type == SolverType::kGaussNewton ? 6 : 30;
    so.seed = 3;
    SolverSummary sc, sg;
    std::vector<float> xc = x0, xg = x0;
    for (Backend* b : {cpu.get(), gpu.get()}) b->SetLevel({shape, scene.geometry, &rays, {}}, RequiredVectors(type));
    Solve(so, cpu.get(), &xc, {}, &sc);
    Solve(so, gpu.get(), &xg, {}, &sg);
    EXPECT_EQ(sg.iterations, sc.iterations) << SolverName(type);
    EXPECT_NEAR(sg.initial_cost, sc.initial_cost, 1e-5 * sc.initial_cost) << SolverName(type);
    EXPECT_NEAR(sg.final_cost, sc.final_cost, 0.03 * sc.final_cost) << SolverName(type);
    EXPECT_LT(sg.final_cost, 0.5 * sg.initial_cost) << SolverName(type);
    std::printf("%s: cost %.6g -> cpu %.6g, cuda %.6g\n", SolverName(type), sc.initial_cost, sc.final_cost,
                sg.final_cost);
  }
}

TEST_F(GpuParityTest, ALevelThatDoesNotFitNamesTheLargestThatDoes) {
  const TinyProblem p = Problem(8);
  CudaBackendOptions o;
  // Room for the rays and a small grid, not for 16^3.
  const LevelProblem big{{16, 8, 2}, p.geometry, &p.rays, {}};
  const LevelProblem small{{4, 2, 2}, p.geometry, &p.rays, {}};
  o.max_memory = gpu->EstimateMemory(small, kVectors).Total() + 1;
  auto b = MakeCudaBackend(o);
  try {
    b->SetLevel(big, kVectors);
    FAIL() << "expected ResourceError";
  } catch (const ResourceError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("16^3 grid"), std::string::npos) << what;
    EXPECT_NE(what.find("largest level that fits"), std::string::npos) << what;
    EXPECT_NE(what.find("4^3 grid"), std::string::npos) << what;
  }
  EXPECT_NO_THROW(b->SetLevel(small, kVectors));
}

// The benchmark's settings at the pass level: ~1.3e5 rays (1000 blocks of 128, so the per-block
// statistics go through CUB's multi-tile reduction, as the ~437 k partials of lego at 256^3 do;
// the small problems above have ~20 blocks, one tile), early termination at 1e-4 (the backward
// pass recomputes the transmittance as exp(-(D - sum)) on rays that stopped), fixed opaque
// shells at a background colour, the alpha residual, rays through pixel centres. A 32^3 grid,
// so that an entry of g sums ~1e3 terms; float atomics against per-thread sums then differ by
// ~sqrt(1e3) eps of the terms' size, and rays that stop one sample apart (transmittance within
// rounding of the threshold) change an entry by < 1e-4 of the colour: entries agree to 2e-4 of
// the largest plus 1e-4 of their own size, costs to 1e-4.
TEST_F(GpuParityTest, ManyRaysWithEarlyTerminationAndFixedShells) {
  TinyProblem p(21, 32, 8, 20, 80, 80);
  ASSERT_EQ(p.rays.size(), 128000);
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (int64_t i = 0; i < p.rays.size(); ++i) p.rays.alphas.push_back(i % 5 == 0 ? 0.f : u(rng));
  // Ten times the densities: rays through the box turn opaque about half way (the CPU here cuts
  // the march from 2.40 M to 1.25 M samples).
  for (int64_t i = 0; i < p.shape.ParamCount(); ++i) {
    if (KindOf(p.shape, i) == ParamKind::kGridDensity) p.x[i] *= 10.f;
  }
  QuantiseColours(&p.rays);
  const float background[3] = {1.f, 1.f, 1.f};
  SetBackgroundShells(p.shape, background, p.x);
  LevelProblem level = p.Level(0.3f, /*pixel_jitter=*/false);
  level.fixed_shells = true;
  level.residuals.stop_transmittance = 0.f;
  cpu->SetLevel(level, kVectors);
  cpu->Upload(kX, p.x);
  const int64_t full_march = cpu->Cost(kX, 3).samples;
  level.residuals.stop_transmittance = 1e-4f;
  enum : VecId { kFree = kVectors };
  SetLevel(level, p.x, kVectors + 1);
  const PassStats cc = cpu->Cost(kX, 3), gc = gpu->Cost(kX, 3);
  // The case exercises early termination: a good part of the march is cut.
  EXPECT_LT(cc.samples, 0.7 * full_march) << "early termination cut " << full_march - cc.samples << " of "
                                          << full_march << " samples";
  EXPECT_NEAR(gc.cost, cc.cost, 1e-4 * cc.cost);
  EXPECT_EQ(gc.rays, cc.rays);
  EXPECT_NEAR(static_cast<double>(gc.samples), static_cast<double>(cc.samples), 1e-3 * cc.samples);

  const PassStats cl = cpu->Linearize(kX, 3, kG, kD), gl = gpu->Linearize(kX, 3, kG, kD, RaySubset{4, 1});
  EXPECT_NEAR(gl.cost, cl.cost, 1e-4 * cl.cost);
  EXPECT_EQ(gl.rays, cl.rays);
  const double subset = cpu->Cost(kX, 3, RaySubset{4, 1}).cost;
  EXPECT_NEAR(gl.subset_cost, subset, 1e-4 * subset);
  test::ExpectAllClose(Get(gpu.get(), kG), Get(cpu.get(), kG), 2e-4, 1e-4, "J^T r, 1e5 rays");
  test::ExpectAllClose(Get(gpu.get(), kD), Get(cpu.get(), kD), 2e-4, 1e-4, "diag(J^T J), 1e5 rays");
  // Reductions over ~1.3e5 parameters (several tiles) of the same vector.
  for (Backend* b : {cpu.get(), gpu.get()}) b->Upload(kOut, Get(cpu.get(), kG));
  EXPECT_NEAR(gpu->Dot(kOut, kOut), cpu->Dot(kOut, kOut), 1e-10 * cpu->Dot(kOut, kOut));
  EXPECT_EQ(gpu->MaxAbs(kOut), cpu->MaxAbs(kOut));

  // CG's product as the solver runs it: fixed shells held, J^T J p on the free parameters.
  for (Backend* b : {cpu.get(), gpu.get()}) b->HoldParameters(kX, kG, kFree, true);
  const std::vector<float> free = Get(cpu.get(), kFree);
  EXPECT_EQ(Get(gpu.get(), kFree), free);
  EXPECT_EQ(std::count(free.begin(), free.end(), 0.f), p.shape.ParamCount() - p.shape.GridParamCount());
  std::normal_distribution<float> normal;
  std::vector<float> pv(p.shape.ParamCount());
  for (size_t i = 0; i < pv.size(); ++i) pv[i] = free[i] * normal(rng);
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->Upload(kP, pv);
    b->RestrictJacobian(kFree);
  }
  const PassStats cj = cpu->MultiplyJtJ(kP, kOut), gj = gpu->MultiplyJtJ(kP, kOut);
  EXPECT_EQ(gj.rays, cj.rays);
  EXPECT_NEAR(static_cast<double>(gj.samples), static_cast<double>(cj.samples), 1e-3 * cj.samples);
  for (Backend* b : {cpu.get(), gpu.get()}) b->Multiply(kOut, kFree);
  test::ExpectAllClose(Get(gpu.get(), kOut), Get(cpu.get(), kOut), 2e-4, 1e-4, "restricted J^T J p, 1e5 rays");
}

// A sparse level (3 of 8 bricks stored): the device reads its own copy of the brick table and
// takes the same samples as the CPU.
TEST_F(GpuParityTest, SparseLevel) {
  TinyProblem p(31, 16, 4, 6, 24, 18);
  QuantiseColours(&p.rays);
  const test::SparseVersion s(p, {0, 1, 1, 0, 0, 0, 1, 0});
  SetLevel(s.level, s.x);
  const PassStats c = cpu->Linearize(kX, 13, kG, kD), g = gpu->Linearize(kX, 13, kG, kD);
  ExpectStatsClose(g, c, "sparse linearize");
  ExpectClose(Get(gpu.get(), kG), Get(cpu.get(), kG), "sparse J^T r");
  ExpectClose(Get(gpu.get(), kD), Get(cpu.get(), kD), "sparse diag(J^T J)");
  std::mt19937 rng(31);
  std::normal_distribution<float> normal;
  std::vector<float> pv(s.level.shape.ParamCount());
  for (float& v : pv) v = normal(rng);
  for (Backend* b : {cpu.get(), gpu.get()}) b->Upload(kP, pv);
  ExpectStatsClose(gpu->MultiplyJtJ(kP, kOut), cpu->MultiplyJtJ(kP, kOut), "sparse J^T J p");
  ExpectClose(Get(gpu.get(), kOut), Get(cpu.get(), kOut), "sparse J^T J p");
  ExpectStatsClose(gpu->Cost(kX, 13), cpu->Cost(kX, 13), "sparse cost");
  const RenderOutput rc = cpu->Render(kX, p.rays.cameras[1], 24, 18, 0.7f);
  const RenderOutput rg = gpu->Render(kX, p.rays.cameras[1], 24, 18, 0.7f);
  test::ExpectAllClose(rg.colour, rc.colour, 1e-4, 1e-4, "sparse render");
}

// The smoothness term (smoothness.h) on a dense and a sparse level: L x, its diagonal, its cost,
// the sums by kind, and a short solve with it.
TEST_F(GpuParityTest, SmoothnessTermAndASolveWithIt) {
  TinyProblem p(37, 16, 4, 6, 24, 18);
  QuantiseColours(&p.rays);
  const test::SparseVersion s(p, {1, 1, 0, 0, 0, 0, 1, 0});
  const SmoothnessWeights w{0.7f, 0.3f, 1.3f, 0.9f};
  for (const auto& [level, x] : {std::pair{LevelProblem{p.shape, p.geometry, &p.rays, {}}, p.x}, std::pair{s.level, s.x}}) {
    SetLevel(level, x);
    double cost[2];
    int k = 0;
    for (Backend* b : {cpu.get(), gpu.get()}) {
      b->Fill(kG, 0.f);
      b->Fill(kD, 0.f);
      b->AddSmoothness(kX, w, kG, kD);
      cost[k++] = b->SmoothnessCost(kX, w);
    }
    EXPECT_NEAR(cost[1], cost[0], 1e-5 * cost[0]);
    ExpectClose(Get(gpu.get(), kG), Get(cpu.get(), kG), "L x");
    ExpectClose(Get(gpu.get(), kD), Get(cpu.get(), kD), "diag(L)");
    const std::array<double, kParamKinds> sc = cpu->SumByKind(kX), sg = gpu->SumByKind(kX);
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(sg[i], sc[i], 1e-6 * std::abs(sc[i])) << "kind " << i;
  }
  SolverOptions o;
  o.max_iterations = 3;
  o.smooth_grid = 0.5;
  o.smooth_shells = 1.0;
  SolverSummary sum[2];
  int k = 0;
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->SetLevel(s.level, RequiredVectors(o.type));
    std::vector<float> x = s.x;
    Solve(o, b, &x, nullptr, &sum[k++]);
  }
  EXPECT_NEAR(sum[1].smoothness.shell_colour, sum[0].smoothness.shell_colour, 1e-5 * sum[0].smoothness.shell_colour);
  EXPECT_NEAR(sum[1].final_cost, sum[0].final_cost, 1e-3 * sum[0].final_cost);
}

// Rays numbered from a global index (a rank's share, RaySet::first_index): the device's jitter
// follows it as the CPU's does, and it matters (the same rays numbered from 0 jitter otherwise).
TEST_F(GpuParityTest, RaysNumberedFromAGlobalIndex) {
  TinyProblem p = Problem(41);
  p.rays.first_index = 1237;
  SetLevel(p.Level(), p.x);
  const PassStats c = cpu->Linearize(kX, 3, kG, kD, RaySubset{5, 2});
  const PassStats g = gpu->Linearize(kX, 3, kG, kD, RaySubset{5, 2});
  ExpectStatsClose(g, c, "linearize, rays from 1237");
  EXPECT_NEAR(g.subset_cost, c.subset_cost, 1e-5 * c.subset_cost);
  ExpectClose(Get(gpu.get(), kG), Get(cpu.get(), kG), "J^T r, rays from 1237");
  ExpectClose(Get(gpu.get(), kD), Get(cpu.get(), kD), "diag, rays from 1237");
  const double from_1237 = gpu->Cost(kX, 3).cost;
  p.rays.first_index = 0;
  SetLevel(p.Level(), p.x);
  EXPECT_NE(gpu->Cost(kX, 3).cost, from_1237) << "first_index must enter the device's jitter";
}

// Two ranks as threads, each with its own CUDA backend on this GPU and half of the rays, summing
// through host copies (Backend::SumAcrossRanks): the passes equal one CUDA backend's.
TEST_F(GpuParityTest, TwoRanksOnOneGpuSumToOneBackend) {
  const TinyProblem p = Problem(43);
  SetLevel(p.Level(), p.x);
  const PassStats one = gpu->Linearize(kX, 8, kG, kD, RaySubset{3, 1});
  const std::vector<float> g1 = Get(gpu.get(), kG), d1 = Get(gpu.get(), kD);
  // Split the rays at a photo boundary, as ranks do.
  const int64_t per_photo = p.rays.size() / static_cast<int64_t>(p.rays.cameras.size());
  const int64_t half = per_photo * static_cast<int64_t>(p.rays.cameras.size() / 2);
  std::vector<RaySet> parts(2);
  for (int r = 0; r < 2; ++r) {
    RaySet& part = parts[static_cast<size_t>(r)];
    part.cameras = p.rays.cameras;  // the pixels keep their camera indices
    const int64_t begin = r == 0 ? 0 : half, end = r == 0 ? half : p.rays.size();
    part.pixels.assign(p.rays.pixels.begin() + begin, p.rays.pixels.begin() + end);
    part.colours.assign(p.rays.colours.begin() + 3 * begin, p.rays.colours.begin() + 3 * end);
    part.first_index = begin;
  }
  test::ThreadGroup group(2);
  std::vector<PassStats> stats(2);
  std::vector<std::vector<float>> g(2), d(2);
  group.Run([&](Communicator& comm) {
    const size_t r = static_cast<size_t>(comm.rank());
    DistributedBackend b(MakeCudaBackend({}), &comm);
    LevelProblem level = p.Level();
    level.rays = &parts[r];
    b.SetLevel(level, kVectors);
    b.Upload(kX, p.x);
    stats[r] = b.Linearize(kX, 8, kG, kD, RaySubset{3, 1});
    g[r] = Get(&b, kG);
    d[r] = Get(&b, kD);
  });
  for (size_t r = 0; r < 2; ++r) {
    ExpectStatsClose(stats[r], one, "2 ranks against 1 (linearize)");
    EXPECT_NEAR(stats[r].subset_cost, one.subset_cost, 1e-5 * one.subset_cost);
    ExpectClose(g[r], g1, "J^T r summed over 2 ranks");
    ExpectClose(d[r], d1, "diag summed over 2 ranks");
    EXPECT_EQ(g[r], g[0]) << "every rank holds the same bits";
  }
}

// A cudaMalloc that fails leaves its error as the runtime's last error; the error path clears
// it, so the next launch check does not report it against an unrelated kernel.
TEST_F(GpuParityTest, AFailedAllocationLeavesNoErrorForTheNextLaunch) {
  const TinyProblem p = Problem(10);
  CudaBackendOptions o;
  o.max_memory = int64_t{1} << 50;  // past the estimate's check: cudaMalloc itself must fail
  auto b = MakeCudaBackend(o);
  const LevelProblem huge{{4096, 8, 2}, p.geometry, &p.rays, {}};  // 1 TiB per solver vector
  try {
    b->SetLevel(huge, kVectors);
    FAIL() << "expected ResourceError";
  } catch (const ResourceError& e) {
    EXPECT_NE(std::string(e.what()).find("out of GPU memory"), std::string::npos) << e.what();
  }
  b->SetLevel(p.Level(), kVectors);  // zero-fills its vectors with a kernel launch
  b->Upload(kX, p.x);
  EXPECT_NO_THROW(b->Cost(kX, 1));
}

// What a level's passes and renders take of the device stays within the level's estimate (its
// vectors, rays, scratch, render band and the kernels' local memory); run first in its own
// process (ctest runs every case alone), the local memory is reserved during this test.
TEST_F(GpuParityTest, TheEstimateCoversWhatALevelUses) {
  const TinyProblem p = Problem(12);
  const int64_t local = cuda::KernelLocalMemoryBytes();
  EXPECT_GT(local, int64_t{64} << 20) << "~1 KB x every thread the device holds";
  const int64_t before = CudaMemoryInUse();
  const MemoryEstimate e = gpu->SetLevel(p.Level(), kVectors);
  EXPECT_GE(e.scratch, local);
  gpu->Upload(kX, p.x);
  gpu->Linearize(kX, 1, kG, kD);
  gpu->Upload(kP, p.x);
  gpu->MultiplyJtJ(kP, kOut);
  gpu->Linearize(kX, 1, kG, kNoVector);
  gpu->Cost(kX, 1);
  gpu->Render(kX, p.rays.cameras[0], 2000, 1500, 0.f);
  const int64_t used = CudaMemoryInUse() - before;
  // Allocation granularity (2 MiB pages) and CUB's launch state.
  EXPECT_LE(used, e.Total() + (int64_t{16} << 20)) << "used " << used << " B, estimated " << e.Total() << " B";
  // With the Jacobian record (allocated by the first Gauss-Newton Linearize): within its estimate too.
  gpu->SetLevel(p.Level(), 1);  // the fixture's level down to one vector
  auto recorded = MakeCudaBackend({});
  const int64_t before_record = CudaMemoryInUse();
  const MemoryEstimate er = recorded->SetLevel(p.Level(), kVectors);
  EXPECT_GT(er.jacobian_cache, 0);
  recorded->Upload(kX, p.x);
  recorded->Linearize(kX, 1, kG, kD);
  recorded->Upload(kP, p.x);
  recorded->MultiplyJtJ(kP, kOut);
  const int64_t used_record = CudaMemoryInUse() - before_record;
  EXPECT_LE(used_record, er.Total() + (int64_t{16} << 20))
      << "used " << used_record << " B, estimated " << er.Total() << " B";
}

// The Jacobian record (ray_record.h), kept by default (CudaBackendOptions::record_jacobian), against
// the fixture's backend, which recomputes every ray, and the CPU's compact record (the same
// bfloat16 storage: ray_record_test runs the device's code on the host against it): J^T J p
// within the compact record's 3e-3 of the recomputed product (cpu_backend_test
// CompactRecordIsTheExactOneRoundedToBfloat16), and within 1e-3 of the CPU's compact one (the
// same bfloat16 values, except where a partial lies within float rounding of a bfloat16 boundary:
// the device's FMAs and expf move partials by ~1e-7 relative); on a dense and a sparse level, with
// spherical harmonics, with exposures, poses and the robust loss, on every ray and on a subset,
// on every parameter and restricted to the free ones (half the densities held). The volume's and
// the photos' entries are compared apart, each on its own scale.
TEST_F(GpuParityTest, RecordedJtJpEqualsTheRecomputedOne) {
  CpuBackendOptions co;
  co.threads = 2;
  co.merged_jacobian = false;  // compact samples
  auto cpu_compact = MakeCpuBackend(co);
  auto recorded = MakeCudaBackend({});
  struct Case {
    std::string name;
    LevelProblem level;
    std::vector<float> x;
    RaySubset jtj;
  };
  std::vector<Case> cases;
  const TinyProblem dense = Problem(51);
  cases.push_back({"dense", dense.Level(), dense.x, {}});
  cases.push_back({"dense, every 3rd ray from 2", dense.Level(), dense.x, {3, 2}});
  TinyProblem sparse(52, 16, 4, 6, 24, 18);
  QuantiseColours(&sparse.rays);
  const test::SparseVersion s(sparse, {0, 1, 1, 0, 0, 0, 1, 0});
  cases.push_back({"sparse", s.level, s.x, {}});
  TinyProblem sh = Problem(53);
  sh.AddSh(1, 54);
  cases.push_back({"degree 1", sh.Level(), sh.x, {}});
  TinyProblem photos = Problem(55);
  photos.AddExposures(56);
  photos.AddPoses(57);
  LevelProblem robust = photos.Level();
  robust.residuals.robust_scale = 0.1f;
  cases.push_back({"exposures, poses, robust loss", robust, photos.x, {}});
  enum : VecId { kFree = kVectors };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const VolumeShape& shape = c.level.shape;
    const std::vector<float> pv = test::RandomDirection(shape, 58);
    std::vector<float> free(shape.ParamCount(), 1.f), held_p = pv;
    for (int64_t cell = 0; cell < shape.StoredCells(); cell += 2) free[GridParam(cell, 3)] = held_p[GridParam(cell, 3)] = 0.f;
    Backend* const backends[] = {gpu.get(), recorded.get(), cpu_compact.get()};
    for (Backend* b : backends) {
      b->SetLevel(c.level, kVectors + 1);
      b->Upload(kX, c.x);
      b->Upload(kFree, free);
      b->Linearize(kX, 11, kG, kD, RaySubset{}, c.jtj);
    }
    EXPECT_TRUE(recorded->CachesJacobian());
    EXPECT_FALSE(gpu->CachesJacobian());
    for (const bool restricted : {false, true}) {
      SCOPED_TRACE(restricted ? "restricted" : "every parameter");
      std::vector<float> out[3];
      PassStats stats[3];
      for (int k = 0; k < 3; ++k) {
        backends[k]->Upload(kP, restricted ? held_p : pv);
        if (restricted) backends[k]->RestrictJacobian(kFree);
        stats[k] = backends[k]->MultiplyJtJ(kP, kOut);
        if (restricted) backends[k]->Multiply(kOut, kFree);
        out[k] = Get(backends[k], kOut);
      }
      EXPECT_EQ(stats[1].rays, stats[0].rays);
      EXPECT_NEAR(static_cast<double>(stats[1].samples), static_cast<double>(stats[0].samples), 1e-3 * stats[0].samples);
      const auto photos_at = static_cast<std::ptrdiff_t>(shape.ExposureStart());
      const auto part = [&](const std::vector<float>& v, bool tail) {
        return tail ? std::vector<float>(v.begin() + photos_at, v.end()) : std::vector<float>(v.begin(), v.begin() + photos_at);
      };
      for (const bool tail : {false, true}) {
        if (tail && shape.exposures == 0) continue;
        SCOPED_TRACE(tail ? "the photos' entries" : "the volume's entries");
        test::ExpectAllClose(part(out[1], tail), part(out[0], tail), 3e-3, 3e-3, "recorded against recomputed");
        test::ExpectAllClose(part(out[1], tail), part(out[2], tail), 1e-3, 1e-3, "recorded against the CPU's compact record");
      }
      EXPECT_NE(out[1], out[0]) << "the record is bfloat16";
    }
  }
  // A short Gauss-Newton solve with the record reaches the recomputing one's cost (to 3 %, as
  // ShortSolvesReachTheSameCost's two backends do).
  const TinyProblem p = Problem(59);
  SolverOptions so;
  so.max_iterations = 6;
  so.seed = 3;
  SolverSummary with, without;
  std::vector<float> xr = p.x, xg = p.x;
  for (Backend* b : {gpu.get(), recorded.get()}) b->SetLevel(p.Level(), RequiredVectors(so.type));
  Solve(so, recorded.get(), &xr, {}, &with);
  Solve(so, gpu.get(), &xg, {}, &without);
  EXPECT_NEAR(with.final_cost, without.final_cost, 0.03 * without.final_cost);
  EXPECT_LT(with.final_cost, 0.8 * with.initial_cost);
}

// A record that does not fit the device memory the level leaves (CudaBackendOptions::max_memory
// here) keeps the rays that find room and recomputes the others, and the level's estimate says
// so (jacobian_wanted: what a whole record would take; the level's log line names both). The
// product then mixes bfloat16 rows and recomputed ones: within 3e-3 of either, equal to neither.
// Below an eighth of the record, none is kept.
TEST_F(GpuParityTest, ARecordThatDoesNotFitRecomputesTheRestAndSaysSo) {
  const TinyProblem p = Problem(60);
  const LevelProblem level = p.Level();
  auto full = MakeCudaBackend({});
  const MemoryEstimate all = full->EstimateMemory(level, kVectors);
  EXPECT_GT(all.jacobian_cache, 0);
  EXPECT_EQ(all.jacobian_wanted, 0);
  const DeviceRecordPlan plan = PlanDeviceRecord(level, int64_t{1} << 40);
  // The backend keeps 256 MiB aside (its margin on so small a budget).
  const int64_t base = all.Needed() + (int64_t{256} << 20) + plan.slots * plan.slot_bytes;
  CudaBackendOptions o;
  o.max_memory = base + plan.wanted / 4 * DeviceRecordPlan::kEntryBytes;
  auto part = MakeCudaBackend(o);
  const MemoryEstimate e = part->SetLevel(level, kVectors);
  EXPECT_TRUE(part->CachesJacobian());
  EXPECT_GT(e.jacobian_cache, 0);
  EXPECT_GT(e.jacobian_wanted, e.jacobian_cache);
  full->SetLevel(level, kVectors);
  gpu->SetLevel(level, kVectors);
  const std::vector<float> pv = test::RandomDirection(level.shape, 61);
  std::vector<float> out[3];
  PassStats stats[3];
  Backend* const backends[] = {gpu.get(), full.get(), part.get()};
  for (int k = 0; k < 3; ++k) {
    backends[k]->Upload(kX, p.x);
    backends[k]->Upload(kP, pv);
    backends[k]->Linearize(kX, 5, kG, kD);
    stats[k] = backends[k]->MultiplyJtJ(kP, kOut);
    out[k] = Get(backends[k], kOut);
  }
  EXPECT_EQ(stats[2].rays, stats[0].rays);
  test::ExpectAllClose(out[2], out[0], 3e-3, 3e-3, "part recorded against recomputed");
  test::ExpectAllClose(out[2], out[1], 3e-3, 3e-3, "part recorded against all recorded");
  EXPECT_NE(out[2], out[0]) << "some rays were recorded";
  EXPECT_NE(out[2], out[1]) << "some rays were recomputed";
  o.max_memory = base + plan.wanted / 10 * DeviceRecordPlan::kEntryBytes;
  auto none = MakeCudaBackend(o);
  const MemoryEstimate n = none->SetLevel(level, kVectors);
  EXPECT_FALSE(none->CachesJacobian());
  EXPECT_EQ(n.jacobian_cache, 0);
}

// A fit crosses between the backends through its checkpoints (issue 61: a workspace fitted on a
// GPU machine exports and scores on a CPU one, and the other way round). Level 1 of two fitted on
// the CPU, written as perf reconstruct writes it and read back, goes on at level 2 on the device
// (as perf reconstruct --resume does: NextLevelShape, Resample); the device's level-2 checkpoint,
// read back, renders on the CPU as the device renders it (what perf export and eval read). Against
// both levels on the CPU: the final costs within 3 % (the solves' paths differ slightly, as in
// ShortSolvesReachTheSameCost).
TEST_F(GpuParityTest, AFitCrossesBetweenTheBackendsThroughItsCheckpoints) {
  const test::SyntheticScene scene(16, 8, 20, 24, 5);
  RaySet rays = MakeRaySet(scene.train);
  QuantiseColours(&rays);
  TrainingViews views;
  for (const PosedImage& p : scene.train) views.views.push_back({p.camera, p.image.width, p.image.height});
  views.rays = [&](int) { return rays; };
  HierarchyOptions o;
  o.levels = 2;
  o.start_resolution = 8;
  o.iterations = 4;
  o.pyramid = false;
  o.solver.seed = 3;
  VolumePlacement placement;
  for (int a = 0; a < 3; ++a) {
    placement.box_center[a] = (&scene.geometry.box.center.x)[a];
    placement.box_size[a] = (&scene.geometry.box.size.x)[a];
    placement.shell_center[a] = (&scene.geometry.shell_center.x)[a];
  }
  for (int i = 0; i < 9; ++i) placement.box_rotation[i] = scene.geometry.box.world_from_box.m[i];
  placement.shell_radii.assign(scene.geometry.shell_radii.begin(), scene.geometry.shell_radii.end());
  // Writes the level a backend finished as a checkpoint and reads it back.
  const auto through_file = [&](const HierarchyLevel& h, const std::vector<float>& x) {
    std::stringstream file;
    WriteCheckpoint(file, {h.level, o.iterations, 0, h.shape, placement, x});
    return ReadCheckpoint(file, "level checkpoint");
  };
  Checkpoint cpu_level1, both_on_cpu, gpu_level2;
  double cost_cpu = 0, cost_crossed = 0;
  HierarchyCallbacks cb;
  cb.level_done = [&](const HierarchyLevel& h, const SolverSummary& summary, const std::vector<float>& x) {
    (h.level == 0 ? cpu_level1 : both_on_cpu) = through_file(h, x);
    if (h.level == 1) cost_cpu = summary.final_cost;
  };
  SolveHierarchy(cpu.get(), scene.geometry, views, o, {}, cb);
  ASSERT_EQ(cpu_level1.shape.n, 8);
  // Level 2 on the device from the CPU's level-1 checkpoint.
  const VolumeGeometry geometry = GeometryOf(cpu_level1);
  HierarchyStart start;
  start.level = 1;
  start.shape = NextLevelShape(o, geometry, cpu_level1.shape, cpu_level1.params, views.views, 1);
  start.x = Resample(cpu_level1.shape, cpu_level1.params, start.shape);
  HierarchyCallbacks gcb;
  gcb.level_done = [&](const HierarchyLevel& h, const SolverSummary& summary, const std::vector<float>& x) {
    gpu_level2 = through_file(h, x);
    cost_crossed = summary.final_cost;
  };
  SolveHierarchy(gpu.get(), geometry, views, o, std::move(start), gcb);
  ASSERT_EQ(gpu_level2.shape.n, 16);
  EXPECT_NEAR(cost_crossed, cost_cpu, 0.03 * cost_cpu);
  EXPECT_EQ(gpu_level2.shape.StoredBricks(), both_on_cpu.shape.StoredBricks()) << "the same level 2 was chosen";
  // The device's checkpoint renders on the CPU as on the device.
  const LevelProblem render_only{gpu_level2.shape, GeometryOf(gpu_level2), nullptr, {}};
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->SetLevel(render_only, 1);
    b->Upload(0, gpu_level2.params);
  }
  const PinholeCamera<float>& camera = scene.test.at(0).camera;
  const RenderOutput rc = cpu->Render(0, camera, 24, 24, 0.f), rg = gpu->Render(0, camera, 24, 24, 0.f);
  test::ExpectAllClose(rg.colour, rc.colour, 1e-4, 1e-4, "the device's checkpoint rendered on both");
  test::ExpectAllClose(rg.opacity, rc.opacity, 1e-4, 1e-4, "its opacity on both");
}

// The 8-bit upload of colours and alphas: rounded to nearest, clamped, NaN to 0 (a cast of NaN
// to an integer is undefined). Host code: runs on every machine.
TEST(ColourToByteTest, RoundsClampsAndMapsNanToZero) {
  EXPECT_EQ(cuda::ColourToByte(0.f), 0);
  EXPECT_EQ(cuda::ColourToByte(1.f), 255);
  EXPECT_EQ(cuda::ColourToByte(0.5f), 128);
  EXPECT_EQ(cuda::ColourToByte(100.f / 255.f), 100);
  EXPECT_EQ(cuda::ColourToByte(-3.f), 0);
  EXPECT_EQ(cuda::ColourToByte(7.f), 255);
  EXPECT_EQ(cuda::ColourToByte(std::numeric_limits<float>::infinity()), 255);
  EXPECT_EQ(cuda::ColourToByte(-std::numeric_limits<float>::infinity()), 0);
  EXPECT_EQ(cuda::ColourToByte(std::numeric_limits<float>::quiet_NaN()), 0);
  EXPECT_EQ(cuda::ColourToByte(-std::numeric_limits<float>::quiet_NaN()), 0);
  for (int b = 0; b < 256; ++b) EXPECT_EQ(cuda::ColourToByte(cuda::ByteToColour(static_cast<uint8_t>(b))), b);
}

// PERF_REQUIRE_GPU turns "no CUDA device" from a skip into a failure. Runs this binary again on
// one GPU case with the device hidden (CUDA_VISIBLE_DEVICES empty), so it checks both ways on any
// machine, with or without a GPU.
struct ChildRun {
  ProcessResult result;
  std::string output;
};
ChildRun RunOneGpuCaseWithoutDevice(const std::string& require_gpu) {
  ChildRun run;
  run.result = RunProcess(std::filesystem::read_symlink("/proc/self/exe"),
                          {"--gtest_filter=GpuParityTest.DescribesTheDevice"},
                          {"CUDA_VISIBLE_DEVICES=", "PERF_REQUIRE_GPU=" + require_gpu, "GTEST_OUTPUT="},
                          [&](std::string_view chunk) { run.output += chunk; });
  return run;
}

TEST(RequireGpuTest, WithoutADeviceGpuCasesSkipUnlessAGpuIsRequired) {
  for (const std::string unset : {"", "0"}) {
    const ChildRun skip = RunOneGpuCaseWithoutDevice(unset);
    EXPECT_EQ(skip.result.signal, 0) << skip.output;
    EXPECT_EQ(skip.result.exit_code, 0) << skip.output;
    EXPECT_NE(skip.output.find("[  SKIPPED ] GpuParityTest.DescribesTheDevice"), std::string::npos) << skip.output;
    EXPECT_NE(skip.output.find("no CUDA device: "), std::string::npos) << skip.output;
  }
  const ChildRun fail = RunOneGpuCaseWithoutDevice("1");
  EXPECT_EQ(fail.result.signal, 0) << fail.output;
  EXPECT_NE(fail.result.exit_code, 0) << fail.output;
  EXPECT_NE(fail.output.find("[  FAILED  ] GpuParityTest.DescribesTheDevice"), std::string::npos) << fail.output;
  EXPECT_NE(fail.output.find("PERF_REQUIRE_GPU is set"), std::string::npos) << fail.output;
  // The reason: no driver here (a machine without one), no device where the driver hides it.
  const bool reason = fail.output.find("driver not found") != std::string::npos ||
                      fail.output.find("no device") != std::string::npos;
  EXPECT_TRUE(reason) << fail.output;
}

}  // namespace
}  // namespace perf::recon
