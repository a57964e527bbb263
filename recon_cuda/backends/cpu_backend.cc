#include "recon_cuda/backends/cpu_backend.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "common/stopwatch.h"
#include "common/system_memory.h"
#include "recon_cuda/backends/cpu_jacobian_record.h"
#include "recon_cuda/backends/cpu_ray_visitors.h"
#include "recon_cuda/backends/cpu_vectors.h"
#include "recon_cuda/core/jacobian.h"
#include "recon_cuda/core/training_ray.h"
#include "recon_cuda/solve/pose_blocks.h"

namespace perf::recon {
namespace {

using namespace cpu;  // the sinks and the Jacobian record (cpu_jacobian_record.h)

constexpr int64_t kBlockRays = 1024;      // rays per task; fixes the cost's summation order

class CpuBackend final : public Backend {
 public:
  explicit CpuBackend(const CpuBackendOptions& o)
      : options_(o), threads_(o.threads > 0 ? o.threads : CoreCount()), vectors_(threads_) {}

  BackendKind kind() const override { return BackendKind::kCpu; }
  std::string Describe() const override { return StrCat("cpu (", threads_, " thread", threads_ == 1 ? "" : "s", ")"); }

  MemoryEstimate EstimateMemory(const LevelProblem& p, int num_vectors) const override {
    return PlanLevel(p, num_vectors, threads_, options_, kBlockRays, vectors_, arena_.size()).memory;
  }

  MemoryEstimate SetLevel(const LevelProblem& problem, int num_vectors) override {
    LevelProblem p = problem;
    if (!p.rays) p.rays = &NoRays();  // render-only
    PERF_CHECK(p.shape.num_shells == p.geometry.num_shells() && p.shape.num_shells <= kMaxShells);
    vectors_.Assign(0, 0);
    blocks_.clear();
    pose_blocks_.clear();
    scratch_.clear();
    level_ = p;
    rays_ = {p.rays->cameras.data(), p.rays->pixels.data(), p.rays->colours.data(),
             UsesAlpha(p) ? p.rays->alphas.data() : nullptr, p.rays->size(), p.rays->first_index,
             PhotoSlots(p, p.shape.exposures), PhotoSlots(p, p.shape.poses)};
    weight_ = OpacityResidualWeight(p);
    robust_ = p.residuals.robust_scale;
    plan_ = PlanLevel(p, num_vectors, threads_, options_, kBlockRays, vectors_, arena_.size());
    level_.start = {};  // the caller's, read by the plan alone
    const MemoryEstimate& e = plan_.memory;
    if (!e.Fits()) {
      throw ResourceError(StrCat("level ", DescribeShape(p.shape), " needs ", e.Needed() >> 20, " MiB for the solver's ",
                                 num_vectors, " vectors, per-thread sums and rays, but only ", e.available >> 20,
                                 " MiB are available; use fewer --levels, fewer --threads, or a larger --downscale"));
    }
    cache_ = options_.cache_jacobian && (e.available == 0 || e.Needed() + e.jacobian_cache <= e.available);
    vectors_.Assign(num_vectors, p.shape.ParamCount());
    const int64_t nblocks = (p.rays->size() + kBlockRays - 1) / kBlockRays;
    if (cache_) blocks_.resize(nblocks);
    arena_.Reset(cache_ ? plan_.ArenaBytes() : 0);  // merged cells: one region for all blocks'
    const float* size = &p.geometry.box.size.x;
    const float longest = std::max({size[0], size[1], size[2]}), shortest = std::min({size[0], size[1], size[2]});
    // The march of any ray: its chord is at most the box diagonal.
    max_samples_ = static_cast<int>(std::ceil(std::sqrt(3.0) * longest / shortest * p.shape.n)) + 2;
    linearized_ = false;
    return e;
  }

  const LevelProblem& level() const override { return level_; }
  bool CachesJacobian() const override { return cache_; }
  void ReleaseJacobian(bool keep_room) override {
    for (BlockJ& b : blocks_) b = BlockJ{};
    if (!keep_room) arena_.Release();
    scratch_.clear();
    linearized_ = false;
  }

  void Upload(VecId v, std::span<const float> host) override { vectors_.Upload(v, host); }
  void Download(VecId v, std::span<float> host) const override { vectors_.Download(v, host); }
  void Fill(VecId v, float value) override { vectors_.Fill(v, value); }
  void SumAcrossRanks(VecId v, Communicator& comm) override { comm.SumInPlace(vectors_[v]); }
  void Copy(VecId dst, VecId src) override { vectors_.Copy(dst, src); }
  void Axpy(VecId y, double a, VecId x) override { vectors_.Axpy(y, a, x); }
  void Xpby(VecId y, VecId x, double b) override { vectors_.Xpby(y, x, b); }
  void DivideClamped(VecId z, VecId r, VecId d, float floor) override { vectors_.DivideClamped(z, r, d, floor); }
  void AxpyDiag(VecId y, double a, VecId d, VecId x) override { vectors_.AxpyDiag(y, a, d, x); }
  double Dot(VecId a, VecId b) const override { return vectors_.Dot(a, b); }
  double MaxAbs(VecId v) const override { return vectors_.MaxAbs(v); }
  double MaxAbsVolume(VecId v) const override { return vectors_.MaxAbs(v, level_.shape.ExposureStart()); }
  void AddSmoothness(VecId v, const SmoothnessWeights& w, VecId out, VecId diag) override {
    vectors_.AddSmoothness(v, level_.shape, w, out, diag);
  }
  double SmoothnessCost(VecId v, const SmoothnessWeights& w) const override {
    return vectors_.SmoothnessCost(v, level_.shape, w);
  }
  std::array<double, kParamKinds> SumByKind(VecId v) const override { return vectors_.SumByKind(v, level_.shape); }
  void Project(VecId x) override { vectors_.Project(x, level_.shape); }
  void HoldParameters(VecId x, VecId g, VecId free, bool bounds) override {
    vectors_.HoldParameters(x, g, free, level_.shape, level_.Held(), bounds);
  }
  void Multiply(VecId y, VecId m) override { vectors_.Multiply(y, m); }
  // Drops the recorded samples that reach no free parameter with a non-zero value (jacobian.h
  // SkippableSample). In carved empty space this is most of the march.
  void RestrictJacobian(VecId free) override {
    if (!linearized_ || !recorded_) return;
    const float* pf = vec(free).data();
    const VolumeView<float> vol = MakeView(level_.shape, level_.geometry, vec(lin_x_).data());
    vectors_.arena().execute([&] {
      tbb::parallel_for(int64_t{0}, static_cast<int64_t>(blocks_.size()), [&](int64_t b) {
        const int64_t ray0 = jtj_.FirstFrom(b * kBlockRays);  // the block's first recorded ray
        const auto ray_of = [&](size_t r) {
          return TrainingRayOf(vol, ray0 + static_cast<int64_t>(r) * jtj_.stride, lin_seed_);
        };
        if (blocks_[b].merged) DropSkippableCells(pf, &blocks_[b]);
        else DropSkippableSamples(vol, pf, ray_of, &blocks_[b]);
      });
    });
  }

  void PreconditionPoses(VecId z, VecId r, VecId diag, VecId free, float floor) override {
    if (level_.shape.poses == 0 || pose_blocks_.empty()) return;
    const int64_t at = level_.shape.PoseStart();
    SolvePoseBlocks(level_.shape.poses, pose_blocks_, vec(r).data() + at, vec(diag).data() + at,
                    vec(free).data() + at, floor, vec(z).data() + at);
  }

  void AdamStep(VecId x, VecId g, VecId m, VecId v, const AdamSettings& s, int t) override {
    vectors_.AdamStep(x, g, m, v, s, t, level_.shape);
  }

  PassStats Linearize(VecId x, uint32_t seed, VecId g, VecId diag, RaySubset subset, RaySubset jtj) override {
    PERF_CHECK(subset.Valid() && jtj.Valid());
    const auto t0 = WallClock::now();
    const VolumeView<float> vol = MakeView(level_.shape, level_.geometry, vec(x).data());
    const bool want_diag = diag != kNoVector;
    const bool record = cache_ && want_diag;  // Adam (no diagonal) never multiplies by J^T J
    const uint64_t pass = BeginPass();
    PassStats stats = ForBlocks(want_diag ? 2 : 1, pass, [&](int64_t block, int64_t begin, int64_t end, Scratch& s) {
      BlockJ* out = record ? &blocks_[block] : nullptr;
      const int64_t room = static_cast<size_t>(block) < plan_.entries.size() ? plan_.entries[block] : 0;
      if (out) out->Clear(jtj.CountIn(begin, end), level_.shape, plan_.record, room, &arena_);
      return want_diag ? LinearizeBlock<true>(vol, seed, subset, jtj, begin, end, s, out)
                       : LinearizeBlock<false>(vol, seed, subset, jtj, begin, end, s, out);
    });
    if (want_diag) {
      ReduceInterleaved(pass, g, diag);
      pose_blocks_.assign(static_cast<size_t>(level_.shape.poses) * kPoseBlock, 0.0);
      for (Scratch& s : scratch_) {
        if (s.pass != pass) continue;
        for (size_t i = 0; i < s.pose_blocks.size(); ++i) pose_blocks_[i] += s.pose_blocks[i];
      }
    } else {
      ReduceInto(pass, g);
    }
    lin_x_ = x;
    lin_seed_ = seed;
    jtj_ = jtj;
    linearized_ = true;
    recorded_ = record;
    stats.seconds = SecondsSince(t0);
    return stats;
  }

  PassStats MultiplyJtJ(VecId p, VecId out) override {
    PERF_CHECK_MSG(linearized_, "MultiplyJtJ before Linearize");
    const auto t0 = WallClock::now();
    const VolumeView<float> vol = MakeView(level_.shape, level_.geometry, vec(lin_x_).data());
    const float* pp = vec(p).data();
    const int k_shells = level_.shape.num_shells;
    const uint64_t pass = BeginPass();
    PassStats stats = ForBlocks(1, pass, [&](int64_t block, int64_t begin, int64_t end, Scratch& s) {
      BlockStats bs;
      AddSink sink{s.acc.data()};
      int64_t r = 0;  // the ray's index in the block's record
      for (int64_t i = jtj_.FirstFrom(begin); i < end; i += jtj_.stride, ++r) {
        const TrainingRay tr = TrainingRayOf(vol, i, lin_seed_);
        const BoxRay<float>& ray = tr.ray;
        const BlockJ* row;  // the ray's record: its `r_row`-th ray, its samples from `first` on, `count` of them
        int64_t r_row = r;
        uint32_t first = 0;
        const float* h;
        float scale;
        int count;
        if (recorded_) {
          const BlockJ& b = blocks_[block];
          row = &b;
          first = r == 0 ? 0 : b.end[r - 1];
          count = static_cast<int>(b.end[r] - first);
          h = &b.h[3 * r];
          scale = b.scale[r];
        } else {
          RecomputeRow(vol, tr, i, s);
          row = &s.row;
          r_row = 0;
          count = static_cast<int>(s.row.samples.size());
          h = s.row.h.data();
          scale = s.row.scale[0];
        }
        const bool pose_row = tr.pose >= 0;
        const PoseRow<float> pr = pose_row ? row->PoseAt(r_row) : PoseRow<float>{};
        const RayExposure<float> e = ExposureAt(vol, i, h, scale);
        const RaySh<float> sh = ShOfRay(vol, ray);
        float u[4] = {0, 0, 0, 0};
        const March<float> m = row->compact ? MakeMarch(vol, ray) : March<float>{};
        RayShellsJ shells;
        RecordedShells(*row, r_row, vol, ray, m, &shells);
        for (int k = 0; k < k_shells; ++k) {
          if (shells.hit[k]) AddJpShell(pp, shells.ts[k], shells.sp[k], u);
        }
        // A merged record (degree 0) holds the ray's cells; else its samples, read here.
        const MergedCells merged{row->merged ? &row->cells[first] : nullptr, row->merged ? count : 0};
        PERF_CHECK(!row->merged || sh.degree == 0);
        merged.AddJp(pp, s.acc.data(), u);
        RecordedSamples read(*row, m, tr.jit, r_row, first);
        GridSample<float>* w = s.weights.data();
        SamplePartials<float>* sp = s.partials.data();
        CellMerger<float, RayCells::K> merger;  // with SH: the ray's cells, merged (RayCells)
        if (sh.degree > 0) s.cells.Begin(pp, s.acc.data(), sh);
        for (int j = 0; j < (row->merged ? 0 : count); ++j) {
          const GridSample<float> gs = TrilinearWeights(vol.n, vol.brick_slot, ray.GridPoint(read.Next(&sp[j])));
          if (sh.degree > 0) {
            merger.Sample(gs, {sp[j].dc, sp[j].ds[0], sp[j].ds[1], sp[j].ds[2], sp[j].dl}, s.cells);
          } else {
            w[j] = gs;
            AddJpSample(pp, gs, sp[j], u, sh);
          }
        }
        if (sh.degree > 0) {
          merger.Finish(s.cells);
          s.cells.AddJp(u);
        }
        if (pose_row) AddJpPose(pr, pp, tr.pose, u);
        FinishJp(e, pp, u);
        float uv[4];
        VolumeU(e, u, uv);
        for (int k = 0; k < k_shells; ++k) {
          if (shells.hit[k]) ScatterJtuShell(shells.ts[k], shells.sp[k], uv, sink);
        }
        if (row->merged) {
          merged.ScatterJtu(uv, s.acc.data());
        } else if (sh.degree > 0) {
          s.cells.ScatterJtu(uv);
        } else {
          // Direct scatter: at degree 0 measured faster than merging cells (RayCells) first.
          for (int j = 0; j < count; ++j) ScatterJtuSample(w[j], sp[j], uv, sink, sh);
        }
        ScatterJtuExposure(e, u, sink);
        if (pose_row) ScatterJtuPose(pr, tr.pose, uv, sink);
        bs.rays += 1;
        bs.samples += count;
      }
      return bs;
    });
    ReduceInto(pass, out);
    stats.seconds = SecondsSince(t0);
    return stats;
  }

  PassStats Cost(VecId x, uint32_t seed, RaySubset subset) override {
    const auto t0 = WallClock::now();
    const VolumeView<float> vol = MakeView(level_.shape, level_.geometry, vec(x).data());
    PERF_CHECK(subset.Valid());
    PassStats stats = ForBlocks(0, 0, [&](int64_t, int64_t begin, int64_t end, Scratch&) {
      BlockStats bs;
      for (int64_t i = subset.FirstFrom(begin); i < end; i += subset.stride) {
        const TrainingRay tr = TrainingRayOf(vol, i, seed);
        const RayOutput<float> fwd =
            Forward(vol, tr.ray, tr.jit, &level_.rays->colours[3 * i], weight_, level_.residuals.stop_transmittance,
                    nullptr, AlphaOf(rays_, i), TransformAt(vol, i));
        bs.Add(fwd, robust_);
      }
      return bs;
    });
    stats.seconds = SecondsSince(t0);
    return stats;
  }

  RenderOutput Render(VecId x, const PinholeCamera<float>& camera, int width, int height,
                      float min_box_opacity) override {
    const VolumeView<float> vol = MakeView(level_.shape, level_.geometry, vec(x).data());
    RenderOutput r;
    r.width = width;
    r.height = height;
    r.colour.resize(static_cast<size_t>(width) * height * 3);
    r.opacity.resize(static_cast<size_t>(width) * height);
    const float zero[3] = {0, 0, 0};
    vectors_.arena().execute([&] {
      tbb::parallel_for(0, height, [&](int y) {
        for (int px = 0; px < width; ++px) {
          const Jitter none{0, 0, false, false};
          const BoxRay<float> ray = PixelBoxRay(camera, level_.geometry.box, vol.n, px, y, none);
          const RayOutput<float> o = Forward(vol, ray, none, zero, 0.f, level_.residuals.stop_transmittance);
          const size_t i = static_cast<size_t>(y) * width + px;
          RulePixel(o, min_box_opacity, &r.colour[3 * i], &r.opacity[i]);
        }
      });
    });
    return r;
  }

 private:
  std::vector<float>& vec(VecId v) { return vectors_[v]; }
  const std::vector<float>& vec(VecId v) const { return vectors_[v]; }

  template <bool kDiag>
  BlockStats LinearizeBlock(const VolumeView<float>& vol, uint32_t seed, RaySubset subset, RaySubset jtj,
                            int64_t begin, int64_t end, Scratch& s, BlockJ* record) const {
    BlockStats bs;
    int64_t r_out = 0;  // the next recorded ray's index in the block's record
    for (int64_t i = begin; i < end; ++i) {
      BlockJ* out = record && jtj.Contains(i) ? record : nullptr;
      const TrainingRay tr = TrainingRayOf(vol, i, seed);
      const BoxRay<float>& ray = tr.ray;
      const Jitter& jit = tr.jit;
      const ColourTransform<float> xf = TransformAt(vol, i);
      const RayOutput<float> fwd =
          Forward(vol, ray, jit, &level_.rays->colours[3 * i], weight_, level_.residuals.stop_transmittance,
                  s.record.data(), AlphaOf(rays_, i), xf);
      const float scale = RobustRowScale(fwd.residual, robust_);
      const RayExposure<float> e = ExposureOfRay(vol.ExposureStart(), ExposureSlotOf(rays_, i), xf, fwd.h, scale);
      float r[4];  // the weighted system's residuals
      ScaledResidual(e, fwd.residual, r);
      LinearizeVisitor<kDiag> v{{}, {}, AddSink{s.acc.data(), kDiag ? 1 : 0, 0},
                                AddSink{kDiag ? s.acc.data() : nullptr, 1, 4}, out,
                                out && !out->compact ? &out->shells[r_out * level_.shape.num_shells] : nullptr,
                                r_out};
      VolumeU(e, r, v.r);
      GainSquared(e, v.g2);
      v.SetSh(ShOfRay(vol, ray));
      v.BeginAhead(s.record.data(), fwd.count);
      if (tr.pose >= 0) {
        GeometryVisitor<float> geometry(vol, ray, jit);
        BothVisitors<LinearizeVisitor<kDiag>, GeometryVisitor<float>> both{v, geometry};
        Backward(vol, ray, jit, fwd, both, s.record.data());
        const PoseRow<float> row = PoseRowOf(vol, vol.params + tr.pose, tr.forward, ray, geometry.grad);
        ScatterJtuPose(row, tr.pose, v.r, v.g);
        if constexpr (kDiag) {
          AddDiagPose(row, tr.pose, v.g2, v.d);
          AddPoseBlock(row, v.g2, &s.pose_blocks[kPoseBlock * ((tr.pose - vol.PoseStart()) / kPoseValues)]);
        }
        if (out) out->StorePose(r_out, row);
      } else {
        Backward(vol, ray, jit, fwd, v, s.record.data());
      }
      v.Finish();
      ScatterJtuExposure(e, r, v.g);
      if constexpr (kDiag) AddDiagExposure(e, v.d);
      if (out) {
        out->end[r_out] = out->SampleCount();
        for (int c = 0; c < 3; ++c) out->h[3 * r_out + c] = fwd.h[c];
        out->scale[r_out] = scale;
        if (out->compact && !out->merged) out->dl_per_delta[r_out] = DlPerDelta(fwd);  // as Backward makes it
        if (out->compact) out->t_box[r_out] = fwd.t_box;  // the shells' partials (RecordedShells)
        ++r_out;
      }
      bs.Add(fwd, robust_, subset.Contains(i));
    }
    return bs;
  }

  // Ray i's photo's colour transform at vol's parameters, and its exposure's partials given H.
  ColourTransform<float> TransformAt(const VolumeView<float>& vol, int64_t i) const {
    return TransformOfRay(rays_, vol, i);
  }
  RayExposure<float> ExposureAt(const VolumeView<float>& vol, int64_t i, const float* h, float scale) const {
    return ExposureOfRay(vol.ExposureStart(), ExposureSlotOf(rays_, i), TransformAt(vol, i), h, scale);
  }

  // Ray i in the iteration of `seed` through its photo's pose at vol.params (training_ray.h, as
  // the CUDA passes read it).
  TrainingRay TrainingRayOf(const VolumeView<float>& vol, int64_t i, uint32_t seed) const {
    return recon::RayOf(rays_, vol, level_.geometry.box, i, seed, level_.residuals.jitter,
                        level_.residuals.pixel_jitter);
  }

  // The partials of ray i at the linearisation point, into s.row (no recorded Jacobian).
  void RecomputeRow(const VolumeView<float>& vol, const TrainingRay& tr, int64_t i, Scratch& s) const {
    const BoxRay<float>& ray = tr.ray;
    const Jitter& jit = tr.jit;
    s.row.Clear(1, level_.shape);
    const RayOutput<float> fwd =
        Forward(vol, ray, jit, &level_.rays->colours[3 * i], weight_, level_.residuals.stop_transmittance,
                s.record.data(), AlphaOf(rays_, i), TransformAt(vol, i));
    RecordOnly visitor{&s.row};
    if (tr.pose >= 0) {
      GeometryVisitor<float> geometry(vol, ray, jit);
      BothVisitors<RecordOnly, GeometryVisitor<float>> both{visitor, geometry};
      Backward(vol, ray, jit, fwd, both, s.record.data());
      s.row.StorePose(0, PoseRowOf(vol, vol.params + tr.pose, tr.forward, ray, geometry.grad));
    } else {
      Backward(vol, ray, jit, fwd, visitor, s.record.data());
    }
    for (int c = 0; c < 3; ++c) s.row.h[c] = fwd.h[c];
    s.row.scale[0] = RobustRowScale(fwd.residual, robust_);
  }

  uint64_t BeginPass() { return ++pass_; }

  // Runs fn(block, begin, end, scratch) over all blocks of rays; with width > 0 the per-thread
  // sums (width floats per parameter) are zeroed on a thread's first block of `pass`. Block
  // statistics are combined in block order.
  template <class Fn>
  PassStats ForBlocks(int width, uint64_t pass, Fn&& fn) {
    const int64_t n = level_.rays->size();
    const int64_t nblocks = (n + kBlockRays - 1) / kBlockRays;
    std::vector<BlockStats> per_block(nblocks);
    const int64_t params = level_.shape.ParamCount();
    vectors_.arena().execute([&] {
      tbb::parallel_for(tbb::blocked_range<int64_t>(0, nblocks, 1), [&](const tbb::blocked_range<int64_t>& r) {
        Scratch& s = scratch_.local();
        if (static_cast<int>(s.record.size()) < max_samples_) {
          s.record.resize(max_samples_);
          s.weights.resize(max_samples_);
          s.partials.resize(max_samples_);
        }
        if (width > 0 && s.pass != pass) {
          s.acc.assign(params * width, 0.f);
          s.pose_blocks.assign(width == 2 ? static_cast<size_t>(level_.shape.poses) * kPoseBlock : 0, 0.0);
          s.pass = pass;
        }
        for (int64_t b = r.begin(); b < r.end(); ++b) {
          per_block[b] = fn(b, b * kBlockRays, std::min(n, (b + 1) * kBlockRays), s);
        }
      });
    });
    PassStats stats;
    for (const BlockStats& b : per_block) {
      stats.cost += b.cost;
      stats.colour_sse += b.colour_sse;
      stats.rays += b.rays;
      stats.samples += b.samples;
      stats.subset_cost += b.subset_cost;
    }
    return stats;
  }

  // The per-thread sums of `pass`.
  std::vector<const float*> SumsOf(uint64_t pass) {
    std::vector<const float*> parts;
    for (Scratch& s : scratch_) {
      if (s.pass == pass && !s.acc.empty()) parts.push_back(s.acc.data());
    }
    return parts;
  }

  // out = the sum of the per-thread sums of `pass`.
  void ReduceInto(uint64_t pass, VecId out) { SumParts(vectors_, SumsOf(pass), vec(out).data()); }

  // g and diag = the sums of the per-thread interleaved sums (AddSink) of `pass`.
  void ReduceInterleaved(uint64_t pass, VecId g, VecId diag) {
    SumInterleavedParts(vectors_, SumsOf(pass), vec(g).data(), vec(diag).data());
  }

  CpuBackendOptions options_;
  int threads_;
  CpuVectors vectors_;  // and the arena every pass runs in
  LevelProblem level_;
  RecordArena arena_;  // the merged cells of blocks_ (declared first: it outlives them)
  std::vector<BlockJ> blocks_;
  std::vector<double> pose_blocks_;  // the last Linearize's pose blocks (pose_blocks.h), with a diagonal
  tbb::enumerable_thread_specific<Scratch> scratch_;
  bool cache_ = false, linearized_ = false, recorded_ = false;
  LevelPlan plan_;  // the level's record and its estimated entries
  int max_samples_ = 0;
  TrainingRays<float> rays_{};     // the level's rays (alphas: nullptr unless UsesAlpha)
  float weight_ = 0;               // OpacityResidualWeight
  float robust_ = 0;               // ResidualSettings::robust_scale
  VecId lin_x_ = kNoVector;
  uint32_t lin_seed_ = 0;
  RaySubset jtj_;  // the last Linearize's rays of MultiplyJtJ (the recorded ones)
  uint64_t pass_ = 0;
};

}  // namespace

std::unique_ptr<Backend> MakeCpuBackend(const CpuBackendOptions& options) {
  // TBB crashes destroying an arena of ~100000 slots (perf render -j 100000 died with SIGSEGV).
  const int most = MaxWorkerThreads();
  if (options.threads < 0 || options.threads > most) {
    throw InputError("command line", "-j/--threads", std::to_string(options.threads),
                     StrCat("must be 0 (all cores) or 1 to ", most, " (8 times this machine's cores)"));
  }
  return std::make_unique<CpuBackend>(options);
}

}  // namespace perf::recon
