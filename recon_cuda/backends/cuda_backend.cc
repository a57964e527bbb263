#include "recon_cuda/backends/cuda_backend.h"

#include <cuda_runtime_api.h>

#include <algorithm>
#include <cstdlib>
#include <vector>

#include "common/errors.h"
#include "common/stopwatch.h"
#include "recon_cuda/backends/cuda_check.h"
#include "recon_cuda/backends/cuda_kernels.h"
#include "recon_cuda/backends/cuda_level_memory.h"
#include "recon_cuda/backends/device_buffer.h"
#include "recon_cuda/backends/device_record_plan.h"
#include "recon_cuda/solve/pose_blocks.h"

namespace perf::recon {
namespace {

using cuda::DeviceBuffer;
using cuda::DeviceRays;
using cuda::DeviceRecord;
using cuda::kRenderBandPixels;
using cuda::RayBytes;
using cuda::Scratch;

std::string Mib(int64_t bytes) { return StrCat((bytes + (1 << 20) - 1) >> 20, " MiB"); }

class CudaBackend final : public Backend {
 public:
  explicit CudaBackend(const CudaBackendOptions& o) : options_(o) {
    int count = 1;
    PERF_CUDA_CHECK(cudaGetDeviceCount(&count));
    options_.device = count > 0 ? o.device % count : 0;  // ranks beyond the devices share them
    PERF_CUDA_CHECK(cudaSetDevice(options_.device));
    cudaDeviceProp prop;
    PERF_CUDA_CHECK(cudaGetDeviceProperties(&prop, options_.device));
    name_ = prop.name;
    if (const char* e = cuda::KernelImageError()) {
      throw ResourceError(StrCat("the CUDA device ", name_, " (compute capability ", prop.major, ".", prop.minor,
                                 ") cannot run this build's kernels (", e,
                                 "); it is built for sm_90 and newer; use --device cpu"));
    }
  }

  BackendKind kind() const override { return BackendKind::kCuda; }
  std::string Describe() const override { return StrCat("cuda (", name_, ")"); }

  MemoryEstimate EstimateMemory(const LevelProblem& p, int num_vectors) const override {
    return EstimateAndPlan(p, num_vectors, nullptr);
  }

  // EstimateMemory, and the level's record (the room the rest leaves, less a margin of 2 % and
  // at least 256 MiB for what the context and the reductions may still take).
  MemoryEstimate EstimateAndPlan(const LevelProblem& p, int num_vectors, DeviceRecordPlan* plan_out) const {
    MemoryEstimate e;
    const int64_t params = p.shape.ParamCount();
    const int64_t rays = p.rays ? p.rays->size() : 0;
    e.vectors = int64_t{num_vectors} * params * 4;
    e.rays = p.rays ? RayBytes(p) : 0;
    // Plus the local memory (stack frames) the driver backs for every thread the device can hold
    // once the ray kernels run: ~1 KB x 132 SMs x 2048 threads = ~285 MB on an H100. It stays
    // with the CUDA context, so after the first level it is counted twice (free memory already
    // lacks it): a margin of a few tenths of a percent of such a device.
    e.scratch = Scratch::Bytes(rays, params) + cuda::KernelLocalMemoryBytes();
    if (p.shape.bricks) {  // the brick table, its list and the march's empty-space table
      const BrickGrid& b = *p.shape.bricks;
      e.scratch += static_cast<int64_t>(b.slot.size() * sizeof(int32_t) + b.bricks.size() * sizeof(int64_t) +
                                        b.skip_blocks.size());
    }
    e.available = Available();
    DeviceRecordPlan plan;
    if (options_.record_jacobian && p.rays) {
      const int64_t margin = std::max<int64_t>(int64_t{256} << 20, e.available / 50);
      plan = PlanDeviceRecord(p, e.available - e.Needed() - margin);
      e.jacobian_cache = plan.Bytes();
      if (plan.Partial()) e.jacobian_wanted = plan.WantedBytes();
    }
    if (plan_out) *plan_out = plan;
    return e;
  }

  MemoryEstimate SetLevel(const LevelProblem& problem, int num_vectors) override {
    LevelProblem p = problem;
    if (!p.rays) p.rays = &NoRays();  // render-only
    PERF_CHECK(p.shape.num_shells == p.geometry.num_shells() && p.shape.num_shells <= kMaxShells);
    PERF_CHECK(num_vectors >= 0);
    Release();
    restrict_to_ = nullptr;
    level_ = p;
    const MemoryEstimate e = EstimateAndPlan(p, num_vectors, &record_plan_);
    if (e.Total() > e.available) throw ResourceError(TooLarge(p, num_vectors, e));
    for (int v = 0; v < num_vectors; ++v) {
      vectors_.emplace_back(p.shape.ParamCount());
      cuda::Fill(vectors_.back().data(), p.shape.ParamCount(), 0.f);
    }
    if (p.shape.bricks) {
      bricks_ = DeviceBuffer<int32_t>(static_cast<int64_t>(p.shape.bricks->slot.size()));
      bricks_.CopyFromHost(p.shape.bricks->slot);
      skip_blocks_ = DeviceBuffer<uint8_t>(static_cast<int64_t>(p.shape.bricks->skip_blocks.size()));
      skip_blocks_.CopyFromHost(p.shape.bricks->skip_blocks);
      brick_list_ = DeviceBuffer<int64_t>(p.shape.bricks->ActiveBricks());
      brick_list_.CopyFromHost(p.shape.bricks->bricks);
    }
    rays_ = std::make_unique<DeviceRays>(*p.rays, UsesAlpha(p), p.shape.exposures, p.shape.poses);
    pose_blocks_ = DeviceBuffer<float>(static_cast<int64_t>(p.shape.poses) * kPoseBlock);
    blocks_fresh_ = false;
    scratch_ = std::make_unique<Scratch>(p.rays->size(), p.shape.ParamCount());
    held_ = e.Total();
    return e;
  }

  const LevelProblem& level() const override { return level_; }
  bool CachesJacobian() const override { return record_plan_.capacity > 0; }
  // Frees the record; the next Linearize with a diagonal allocates it again.
  void ReleaseJacobian(bool) override {
    record_.reset();
    recorded_ = false;
    linearized_ = false;
  }

  void Upload(VecId v, std::span<const float> host) override { vec(v).CopyFromHost(host); }
  void Download(VecId v, std::span<float> host) const override { vec(v).CopyToHost(host); }
  void SumAcrossRanks(VecId v, Communicator& comm) override {
    if (!comm.SumDeviceInPlace(ptr(v), static_cast<size_t>(n()))) Backend::SumAcrossRanks(v, comm);
  }
  void Fill(VecId v, float value) override { cuda::Fill(ptr(v), n(), value); }
  void Copy(VecId dst, VecId src) override { cuda::Copy(ptr(dst), ptr(src), n()); }
  void Axpy(VecId y, double a, VecId x) override { cuda::Axpy(ptr(y), static_cast<float>(a), ptr(x), n()); }
  void Xpby(VecId y, VecId x, double b) override { cuda::Xpby(ptr(y), ptr(x), static_cast<float>(b), n()); }
  void DivideClamped(VecId z, VecId r, VecId d, float floor) override {
    cuda::DivideClamped(ptr(z), ptr(r), ptr(d), floor, n());
  }
  void AxpyDiag(VecId y, double a, VecId d, VecId x) override {
    cuda::AxpyDiag(ptr(y), static_cast<float>(a), ptr(d), ptr(x), n());
  }
  double Dot(VecId a, VecId b) const override { return cuda::Dot(ptr(a), ptr(b), n(), scratch_->Reduce()); }
  double MaxAbs(VecId v) const override { return cuda::MaxAbs(ptr(v), n(), scratch_->Reduce()); }
  double MaxAbsVolume(VecId v) const override {
    return cuda::MaxAbs(ptr(v), level_.shape.ExposureStart(), scratch_->Reduce());
  }
  void AddSmoothness(VecId v, const SmoothnessWeights& w, VecId out, VecId diag) override {
    PERF_CHECK(out != v);
    cuda::AddSmoothness(ptr(v), DeviceSmoothnessLayout(), w, out == kNoVector ? nullptr : ptr(out),
                        diag == kNoVector ? nullptr : ptr(diag), n());
  }
  double SmoothnessCost(VecId v, const SmoothnessWeights& w) const override {
    return cuda::SmoothnessCost(ptr(v), DeviceSmoothnessLayout(), w, n(), scratch_->Reduce());
  }
  std::array<double, kParamKinds> SumByKind(VecId v) const override {
    return cuda::SumByKind(ptr(v), n(), level_.shape.Layout(), scratch_->Reduce());
  }
  void Project(VecId x) override {
    cuda::Project(ptr(x), n(), level_.shape.Layout());
  }
  void HoldParameters(VecId x, VecId g, VecId free, bool bounds) override {
    cuda::HoldParameters(ptr(x), ptr(g), ptr(free), n(), level_.shape.Layout(),
                         level_.Held(), bounds);
  }
  void Multiply(VecId y, VecId m) override { cuda::Multiply(ptr(y), ptr(m), n()); }
  // The blocks are solved on the host: a photo's 7 values, a few hundred photos (pose_blocks.h).
  void PreconditionPoses(VecId z, VecId r, VecId diag, VecId free, float floor) override {
    const int poses = level_.shape.poses;
    if (poses == 0 || !blocks_fresh_) return;
    const int64_t at = level_.shape.PoseStart(), count = static_cast<int64_t>(poses) * kPoseValues;
    std::vector<float> blocks(pose_blocks_.size()), hr(count), hd(count), hf(count), hz(count);
    pose_blocks_.CopyToHost(blocks);
    const auto get = [&](VecId v, std::vector<float>& host) {
      PERF_CUDA_CHECK(cudaMemcpy(host.data(), ptr(v) + at, count * sizeof(float), cudaMemcpyDeviceToHost));
    };
    get(r, hr);
    get(diag, hd);
    get(free, hf);
    const std::vector<double> wide(blocks.begin(), blocks.end());
    SolvePoseBlocks(poses, wide, hr.data(), hd.data(), hf.data(), floor, hz.data());
    PERF_CUDA_CHECK(cudaMemcpy(ptr(z) + at, hz.data(), count * sizeof(float), cudaMemcpyHostToDevice));
  }
  // Nothing is dropped from the record: both J^T J p kernels skip the samples on the fly
  // (jacobian.h SkippableSample).
  void RestrictJacobian(VecId free) override { restrict_to_ = ptr(free); }
  void AdamStep(VecId x, VecId g, VecId m, VecId v, const AdamSettings& s, int t) override {
    cuda::AdamStep(ptr(x), ptr(g), ptr(m), ptr(v), AdamCoefficientsAt(s, t), n(), level_.shape.Layout());
  }

  PassStats Linearize(VecId x, uint32_t seed, VecId g, VecId diag, RaySubset subset, RaySubset jtj) override {
    PERF_CHECK(subset.Valid() && jtj.Valid());
    const auto t0 = WallClock::now();
    const RecordView rec = diag != kNoVector && Record(jtj) ? record_->View(jtj) : RecordView{};
    const cuda::RayStats r =
        cuda::Linearize(Input(x, seed), ptr(g), diag == kNoVector ? nullptr : ptr(diag),
                        pose_blocks_.size() > 0 ? pose_blocks_.data() : nullptr, rec, n(), subset.stride,
                        subset.offset, scratch_->Stats());
    recorded_ = rec.heads != nullptr;
    every_ray_recorded_ = recorded_ && cuda::RecordedEntries(rec) <= rec.capacity;
    blocks_fresh_ = diag != kNoVector && pose_blocks_.size() > 0;
    lin_x_ = x;
    lin_seed_ = seed;
    jtj_ = jtj;
    linearized_ = true;
    restrict_to_ = nullptr;
    return ToPassStats(r, t0);
  }

  PassStats MultiplyJtJ(VecId p, VecId out) override {
    PERF_CHECK_MSG(linearized_, "MultiplyJtJ before Linearize");
    const auto t0 = WallClock::now();
    const RecordView rec = recorded_ ? record_->View(jtj_) : RecordView{};
    const cuda::RayStats r =
        cuda::MultiplyJtJ(Input(lin_x_, lin_seed_), ptr(p), restrict_to_, ptr(out), n(), jtj_.stride, jtj_.offset,
                          scratch_->Stats(), rec, recorded_ && !every_ray_recorded_);
    return ToPassStats(r, t0);
  }

  PassStats Cost(VecId x, uint32_t seed, RaySubset subset) override {
    PERF_CHECK(subset.Valid());
    const auto t0 = WallClock::now();
    return ToPassStats(cuda::Cost(Input(x, seed), subset.stride, subset.offset, scratch_->Stats()), t0);
  }

  RenderOutput Render(VecId x, const PinholeCamera<float>& camera, int width, int height,
                      float min_box_opacity) override {
    PERF_CHECK(width >= 0 && height >= 0);
    RenderOutput r;
    r.width = width;
    r.height = height;
    const int64_t pixels = static_cast<int64_t>(width) * height;
    r.colour.resize(3 * pixels);
    r.opacity.resize(pixels);
    if (pixels == 0) return r;
    PERF_CHECK_MSG(width <= kRenderBandPixels, "a render ", width, " pixels wide");
    const int band = static_cast<int>(std::min<int64_t>(height, kRenderBandPixels / width));
    for (int y0 = 0; y0 < height; y0 += band) {
      const int rows = std::min(band, height - y0);
      const int64_t first = static_cast<int64_t>(y0) * width, count = static_cast<int64_t>(rows) * width;
      cuda::Render(View(ptr(x)), level_.geometry.box, camera, width, y0, rows,
                   level_.residuals.stop_transmittance, min_box_opacity, scratch_->render_colour.data(),
                   scratch_->render_opacity.data());
      scratch_->render_colour.CopyPrefixToHost(std::span<float>(r.colour).subspan(3 * first, 3 * count));
      scratch_->render_opacity.CopyPrefixToHost(std::span<float>(r.opacity).subspan(first, count));
    }
    return r;
  }

 private:
  // Whether the record is kept for the rays of jtj: the level planned one with a slot for each of
  // them; allocated here on the level's first Gauss-Newton Linearize (Adam's never asks). Should
  // the device refuse the memory then (another process took it since SetLevel's estimate), the
  // level recomputes instead.
  bool Record(RaySubset jtj) {
    if (record_plan_.capacity == 0) return false;
    if (SubsetRays(level_.rays->size(), jtj) > record_plan_.slots) return false;
    if (!record_) {
      try {
        record_ = std::make_unique<DeviceRecord>(record_plan_, level_.shape);
      } catch (const ResourceError&) {
        record_plan_.capacity = 0;
        return false;
      }
    }
    return true;
  }
  static int64_t SubsetRays(int64_t rays, RaySubset s) { return s.CountIn(0, rays); }

  void Release() {
    record_.reset();
    record_plan_ = {};
    recorded_ = false;
    vectors_.clear();
    bricks_ = DeviceBuffer<int32_t>();
    skip_blocks_ = DeviceBuffer<uint8_t>();
    brick_list_ = DeviceBuffer<int64_t>();
    rays_.reset();
    scratch_.reset();
    pose_blocks_ = DeviceBuffer<float>();
    blocks_fresh_ = false;
    held_ = 0;
    linearized_ = false;
  }

  // What the backend may use: free device memory plus what it holds now (SetLevel frees that
  // first), less 5 % for the CUDA context's own growth and fragmentation.
  int64_t Available() const {
    if (options_.max_memory > 0) return options_.max_memory;
    size_t free = 0, total = 0;
    PERF_CUDA_CHECK(cudaMemGetInfo(&free, &total));
    return (static_cast<int64_t>(free) + held_) / 20 * 19;
  }

  // The ResourceError message: what the level needs, what is free, and the largest grid that
  // would fit with the same rays.
  std::string TooLarge(const LevelProblem& p, int num_vectors, const MemoryEstimate& e) const {
    std::string hint;
    for (VolumeShape s = p.shape; s.n >= 2;) {
      s = {s.n / 2, std::max(1, s.m / 2), s.num_shells};
      LevelProblem q = p;
      q.shape = s;
      const MemoryEstimate f = EstimateMemory(q, num_vectors);
      if (f.Total() <= e.available) {
        hint = StrCat("the largest level that fits with these rays is ", DescribeShape(s), " (", Mib(f.Total()),
                      "): use fewer --levels");
        break;
      }
    }
    if (hint.empty()) hint = StrCat("the rays alone need ", Mib(e.rays), ": use a larger --downscale");
    return StrCat("level ", DescribeShape(p.shape), " needs ", Mib(e.Total()), " of GPU memory (", num_vectors,
                  " solver vectors ", Mib(e.vectors), ", ", p.rays->size(), " rays ", Mib(e.rays),
                  ", scratch and the kernels' local memory ", Mib(e.scratch), ") but only ", Mib(e.available), " are free on ", name_, "; ", hint,
                  ", a larger --downscale, or --device cpu");
  }

  // The smoothness stencil's layout with a sparse grid's tables on the device.
  SmoothnessLayout DeviceSmoothnessLayout() const {
    SmoothnessLayout layout = MakeSmoothnessLayout(level_.shape);
    if (level_.shape.bricks) {
      layout.slot = bricks_.data();
      layout.bricks = brick_list_.data();
    }
    return layout;
  }

  // The level's volume at x as the kernels read it: a sparse grid's brick table on the device.
  VolumeView<float> View(const float* x) const {
    VolumeView<float> v = MakeView(level_.shape, level_.geometry, x);
    if (v.brick_slot) {
      v.brick_slot = bricks_.data();
      v.skip_blocks = skip_blocks_.data();
    }
    return v;
  }

  cuda::PassInput Input(VecId x, uint32_t seed) const {
    return {View(ptr(x)),
            level_.geometry.box,
            rays_->View(),
            OpacityResidualWeight(level_),
            level_.residuals.stop_transmittance,
            level_.residuals.jitter,
            level_.residuals.pixel_jitter,
            seed,
            level_.residuals.robust_scale};
  }

  static PassStats ToPassStats(const cuda::RayStats& r, WallClock::time_point t0) {
    PassStats s;
    s.cost = r.cost;
    s.colour_sse = r.colour_sse;
    s.rays = r.rays;
    s.samples = r.samples;
    s.subset_cost = r.subset_cost;
    s.seconds = SecondsSince(t0);  // the pass has synchronised (its statistics are on the host)
    return s;
  }

  DeviceBuffer<float>& vec(VecId v) {
    PERF_CHECK(v >= 0 && v < static_cast<int>(vectors_.size()));
    return vectors_[v];
  }
  const DeviceBuffer<float>& vec(VecId v) const {
    PERF_CHECK(v >= 0 && v < static_cast<int>(vectors_.size()));
    return vectors_[v];
  }
  float* ptr(VecId v) { return vec(v).data(); }
  const float* ptr(VecId v) const { return vec(v).data(); }
  int64_t n() const { return level_.shape.ParamCount(); }

  CudaBackendOptions options_;
  std::string name_;
  LevelProblem level_;
  std::vector<DeviceBuffer<float>> vectors_;
  DeviceBuffer<int32_t> bricks_;  // a sparse level's brick table (VolumeView::brick_slot)
  DeviceBuffer<uint8_t> skip_blocks_;  // its empty-space table (VolumeView::skip_blocks)
  DeviceBuffer<int64_t> brick_list_;  // and the brick of each slot (SmoothnessLayout::bricks)
  std::unique_ptr<DeviceRays> rays_;
  DeviceBuffer<float> pose_blocks_;  // [poses, kPoseBlock] of the last Linearize with a diagonal
  bool blocks_fresh_ = false;        // whether pose_blocks_ are of the last linearisation
  std::unique_ptr<Scratch> scratch_;
  int64_t held_ = 0;  // bytes of the current level (EstimateMemory's Total)
  bool linearized_ = false;
  VecId lin_x_ = kNoVector;
  uint32_t lin_seed_ = 0;
  RaySubset jtj_;  // the last Linearize's rays of MultiplyJtJ
  const float* restrict_to_ = nullptr;  // RestrictJacobian's free vector until the next Linearize
  DeviceRecordPlan record_plan_;        // the level's record (capacity 0: none)
  std::unique_ptr<DeviceRecord> record_;  // allocated by the level's first Gauss-Newton Linearize
  bool recorded_ = false;               // the last Linearize recorded its jtj rays
  bool every_ray_recorded_ = false;     // ... and every one of them found room
};

}  // namespace

std::unique_ptr<Backend> MakeCudaBackend(const CudaBackendOptions& options) {
  std::string reason;
  if (!ProbeCudaDevice(nullptr, &reason)) {
    throw ResourceError(StrCat("no CUDA device: ", reason, "; use --device cpu"));
  }
  return std::make_unique<CudaBackend>(options);
}

}  // namespace perf::recon
