// The ray passes of the CUDA backend: one thread per ray (per pixel for Render), calling the
// per-ray code of ray_math.h and jacobian.h, with float atomics as the scatter sink. Nothing of
// the per-ray math is written here; this file adds launches, the sink and the statistics.
//
// Differences from the CPU backend, by design:
//   - the Jacobian record (ray_record.h) is the CPU's compact one (9 bytes a sample, no merged
//     cells: at 24 bytes a cell and 4-5 cells a sample it would not fit a 256^3 level), each
//     ray's entries contiguous at an offset handed out a warp at a time while Linearize runs
//     (ReserveEntries); JtJpRecordKernel reads them. Rays that find no room (the record is sized
//     to the memory the level leaves: device_record_plan.h) are recomputed by JtJpKernel
//     (Forward, then Backward twice: once gathering J p, once scattering J^T (J p)), as every ray
//     is with CudaBackendOptions::record_jacobian off;
//   - J^T u scatters (Adam's gradient, J^T J p) go through the per-ray cell merge (CellMerger),
//     so each cell gets one atomic per ray instead of one per sample (the CPU measured a direct
//     scatter faster because its adds are plain; on the GPU atomics to the same few cells from a
//     warp's neighbouring rays serialise);
//   - the merged scatter adds 4 consecutive floats; on sm_90 that is one vector atomic (float4),
//     elsewhere 4 scalar ones. Every Add4 index is a multiple of 4 (GridParam / ShellParam of
//     channel 0) and cudaMalloc aligns to 256 bytes, so the float4 is aligned.
// Resources (ptxas -v, CUDA 13.0.88, sm_90, 2026-12-07; re-measure after changing the per-ray
// code): Linearize with diag (and the record's writer) 235 registers + 1296 B stack frame, with
// poses 255 + 2120 B and 178 B of spill stores; for Adam 168 + 1040 B; JtJpRecordKernel 168 +
// 1408 B (no spills; with __launch_bounds__ min 4 blocks: 128 + 1600 B, 252 B spilled), JtJpKernel
// 168 + 1072 B (poses: 255 + 1896 B, 116 B spilled), Cost 96 + 328 B, Render 80 + 448 B. The stack
// holds the cell merge buffers and the per-shell arrays (indexed at run time); the driver backs it
// for every thread the device can hold (KernelLocalMemoryBytes: ~285 MB on an H100, part of the
// memory estimate). At 235 registers 2 blocks of 128 threads fit an SM's 64 K registers: 12.5 %
// occupancy for Gauss-Newton's Linearize. That is the first thing to profile on a GPU (Nsight
// Compute: is the kernel latency-bound, what do __launch_bounds__ min-blocks or smaller merge
// buffers cost in local memory traffic?); do not tune it blind.
// Float atomics make the order of the additions, hence the last bits of g, diag and J^T J p,
// vary from run to run; the cost and counts are summed per block with CUB in a fixed order.
#include <cub/device/device_reduce.cuh>

#include "common/errors.h"
#include "recon_cuda/backends/cuda_check.h"
#include "recon_cuda/backends/cuda_kernels.h"
#include "recon_cuda/backends/cuda_pass_helpers.cuh"
#include "recon_cuda/core/jacobian.h"
#include "recon_cuda/core/ray_record.h"

namespace perf::recon::cuda {
namespace {

using namespace pass;  // the kernels' shared pieces (cuda_pass_helpers.cuh)

// The ray's scatter of J^T u (u: the residuals for the gradient, J p for J^T J p) and, with
// kDiag, its exact share of diag(J^T J), merged cell by cell along the ray (jacobian.h).
// free: J^T J p restricted to these parameters (SkippableSample), or nullptr.
template <bool kDiag>
struct ScatterVisitor {
  static constexpr int K = kDiag ? 9 : 4;  // J^T u values, then the 5 row values of diag
  float u[4];
  AtomicSink g, d;
  CellMerger<float, K> merger;
  const float* free = nullptr;
  float g2[3] = {1, 1, 1};  // the squared gains of the ray's photo (jacobian.h GainSquared)
  RaySh<float> sh{};        // the ray's spherical harmonics (degree 0: none)
  RecordWriter record{};    // with kDiag: the ray's entries of the Jacobian record (ray_record.h)

  __device__ void Shell(int, const CubeCoord<float>&, const TexelSample<float>& ts, const ShellPartials<float>& sp) {
    ScatterJtuShell(ts, sp, u, g);
    if constexpr (kDiag) AddDiagShell(ts, sp, g2, d);
  }
  __device__ void Sample(int k, const MarchStep<float>&, const GridSample<float>& gs, const SamplePartials<float>& sp) {
    if constexpr (kDiag) record.Sample(k, sp);
    if (free && SkippableSample(gs, sp, free)) return;
    float v[K];
    JtuValues(sp, u, v);
    if constexpr (kDiag) RowValues(sp, v + 4);
    merger.Sample(gs, v, *this);
  }
  // A cell's merged sums are complete.
  __device__ void operator()(int64_t cell, const float* acc) {
    g.Add4(GridParam(cell, 0), acc[0], acc[1], acc[2], acc[3]);
    if constexpr (kDiag) AddDiagFromRow(cell, acc + 4, g2, d);
    if (sh.degree > 0) {
      ScatterSh(sh, cell, acc, g);
      if constexpr (kDiag) AddDiagSh(sh, cell, acc[4], g2, d);
    }
  }
  __device__ void Finish() { merger.Finish(*this); }
};

// u += J_ray p (a gather); free as in ScatterVisitor. used: the grid samples gathered.
struct JpVisitor {
  const float* p;
  const float* free;
  float u[4];
  RaySh<float> sh{};
  int used = 0;
  __device__ void Shell(int, const CubeCoord<float>&, const TexelSample<float>& ts, const ShellPartials<float>& sp) {
    AddJpShell(p, ts, sp, u);
  }
  __device__ void Sample(int, const MarchStep<float>&, const GridSample<float>& gs, const SamplePartials<float>& sp) {
    if (free && SkippableSample(gs, sp, free)) return;
    AddJpSample(p, gs, sp, u, sh);
    ++used;
  }
};

// kPoses: the level refines the photos' poses (pose.h): the kernels also sweep the geometry
// visitor and add the pose rows. A template argument, so that the kernels of a level without
// poses keep their registers. With kDiag (Gauss-Newton), the rays of rec's subset write their
// entries of the Jacobian record as Backward visits their samples (rec.heads nullptr: none do).
template <bool kDiag, bool kPoses>
__global__ void __launch_bounds__(kRayThreads) LinearizeKernel(PassInput in, float* g, float* diag, float* pose_blocks,
                                                               RecordView rec, int stride, int offset,
                                                               RayStats* partials) {
  const int64_t i = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  RayStats mine;
  ExposureSums eg, ed, pg, pd;
  GroupSums<kPoses && kDiag ? kPoseBlock : 4> pb;
  if (i < in.rays.count) {
    const TrainingRay r = MakeRay(in, i);
    float target[3];
    TargetOf(in.rays, i, target);
    const int slot = ExposureSlotOf(in.rays, i);
    const ColourTransform<float> xf = TransformOfRay(in.rays, in.vol, i);
    const RayOutput<float> fwd =
        Forward(in.vol, r.ray, r.jit, target, in.lambda, in.stop_transmittance, nullptr, AlphaOf(in.rays, i), xf);
    const RayExposure<float> e =
        ExposureOfRay(in.vol.ExposureStart(), slot, xf, fwd.h, RobustRowScale(fwd.residual, in.robust));
    float rs[4];  // the weighted system's residuals
    ScaledResidual(e, fwd.residual, rs);
    ScatterVisitor<kDiag> v{{0, 0, 0, 0}, {g}, {diag}, {}};
    VolumeU(e, rs, v.u);
    GainSquared(e, v.g2);
    v.sh = ShOfRay(in.vol, r.ray);
    bool records = false;
    int64_t first = -1;
    if constexpr (kDiag) {
      records = rec.Records(i);
      if (records) {
        first = ReserveEntries(rec, EntriesToReserve(fwd));
        v.record.Begin(rec, first);
      }
    }
    if constexpr (kPoses) {
      GeometryVisitor<float> geometry(in.vol, r.ray, r.jit);
      BothVisitors<ScatterVisitor<kDiag>, GeometryVisitor<float>> both{v, geometry};
      Backward(in.vol, r.ray, r.jit, fwd, both);
      if (r.pose >= 0) {
        const PoseRow<float> row = PoseRowOf(in.vol, in.vol.params + r.pose, r.forward, r.ray, geometry.grad);
        if (records) {
          FinishRecord(rec, i, first, v.record, fwd, e.scale, &row);
          records = false;
        }
        pg.base = pd.base = r.pose;
        ScatterJtuPose(row, r.pose, v.u, pg);
        if constexpr (kDiag) {
          AddDiagPose(row, r.pose, v.g2, pd);
          pb.base = kPoseBlock * ((r.pose - in.vol.PoseStart()) / kPoseValues);
          AddPoseBlock(row, v.g2, pb.v);
        }
      }
    } else {
      Backward(in.vol, r.ray, r.jit, fwd, v);
    }
    if (records) FinishRecord(rec, i, first, v.record, fwd, e.scale, nullptr);
    v.Finish();
    eg.base = ed.base = e.param;
    ScatterJtuExposure(e, rs, eg);
    if constexpr (kDiag) AddDiagExposure(e, ed);
    mine = StatsOf(fwd, in.robust);
    if (i % stride == offset) mine.subset_cost = mine.cost;
  }
  WarpAddExposure(eg, g);
  if constexpr (kDiag) WarpAddExposure(ed, diag);
  if constexpr (kPoses) {
    WarpAddExposure(pg, g);
    if constexpr (kDiag) {
      WarpAddExposure(pd, diag);
      WarpAddGroup(pb, pose_blocks);
    }
  }
  WriteBlockStats(mine, partials);
}

// Thread j multiplies ray offset + j stride of `count` such rays.
// recorded: the Jacobian record's heads of these rays (slot j), whose recorded rays are left to
// JtJpRecordKernel; nullptr: none are.
template <bool kPoses>
__global__ void __launch_bounds__(kRayThreads) JtJpKernel(PassInput in, const float* p, const float* free,
                                                          float* out, int64_t stride, int64_t offset,
                                                          int64_t count, const RayRecordHead* recorded,
                                                          RayStats* partials) {
  const int64_t j = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  RayStats mine;
  ExposureSums eo, po;
  if (j < count && !(recorded && recorded[j].first >= 0)) {
    const int64_t i = offset + j * stride;
    const TrainingRay r = MakeRay(in, i);
    // The partials depend on the forward's transmittances and colours (and on whether the ray
    // has an alpha, not on its value); the exposure's on H; the robust row scale on the residual.
    float target[3];
    TargetOf(in.rays, i, target);
    const ColourTransform<float> xf = TransformOfRay(in.rays, in.vol, i);
    const RayOutput<float> fwd =
        Forward(in.vol, r.ray, r.jit, target, in.lambda, in.stop_transmittance, nullptr, AlphaOf(in.rays, i), xf);
    const RayExposure<float> e = ExposureOfRay(in.vol.ExposureStart(), ExposureSlotOf(in.rays, i), xf, fwd.h,
                                               RobustRowScale(fwd.residual, in.robust));
    JpVisitor jp{p, free, {0, 0, 0, 0}};
    jp.sh = ShOfRay(in.vol, r.ray);
    PoseRow<float> row;
    if constexpr (kPoses) {
      GeometryVisitor<float> geometry(in.vol, r.ray, r.jit);
      BothVisitors<JpVisitor, GeometryVisitor<float>> both{jp, geometry};
      Backward(in.vol, r.ray, r.jit, fwd, both);
      if (r.pose >= 0) {
        row = PoseRowOf(in.vol, in.vol.params + r.pose, r.forward, r.ray, geometry.grad);
        AddJpPose(row, p, r.pose, jp.u);
      }
    } else {
      Backward(in.vol, r.ray, r.jit, fwd, jp);
    }
    FinishJp(e, p, jp.u);
    ScatterVisitor<false> v{{0, 0, 0, 0}, {out}, {nullptr}, {}, free};
    VolumeU(e, jp.u, v.u);
    v.sh = jp.sh;
    Backward(in.vol, r.ray, r.jit, fwd, v);
    v.Finish();
    eo.base = e.param;
    ScatterJtuExposure(e, jp.u, eo);
    if constexpr (kPoses) {
      if (r.pose >= 0) {
        po.base = r.pose;
        ScatterJtuPose(row, r.pose, v.u, po);
      }
    }
    mine.rays = 1;
    // The samples that enter the product, as the CPU backend counts them when it records the
    // Jacobian (after RestrictJacobian it visits only the samples it kept; recomputing, it counts
    // every sample). The march itself visits fwd.count, so after RestrictJacobian J^T J p's
    // samples/s is not a march rate.
    mine.samples = jp.used;
  }
  WarpAddExposure(eo, out);
  if constexpr (kPoses) WarpAddExposure(po, out);
  WriteBlockStats(mine, partials);
}

// J^T J p from the Jacobian record (ray_record.h RecordedJtJp): thread j multiplies ray
// rec.offset + j rec.stride of `count` such rays when it is recorded (the rest: JtJpKernel).
// Nothing is marched: the ray's entries give its samples' positions and partials, and its shells
// are looked up once.
template <bool kPoses>
__global__ void __launch_bounds__(kRayThreads) JtJpRecordKernel(PassInput in, RecordView rec, const float* p,
                                                                const float* free, float* out, int64_t count,
                                                                RayStats* partials) {
  const int64_t j = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  RayStats mine;
  ExposureSums eo, po;
  if (j < count && rec.heads[j].first >= 0) {
    const int64_t i = rec.offset + j * rec.stride;
    const TrainingRay r = MakeRay(in, i);
    const RayExposure<float> e = RecordedExposure(rec, i, in.vol.ExposureStart(), ExposureSlotOf(in.rays, i),
                                                  TransformOfRay(in.rays, in.vol, i));
    eo.base = e.param;
    if constexpr (kPoses) po.base = r.pose;
    AtomicSink sink{out};
    mine.samples = RecordedJtJp(rec, i, in.vol, r, e, p, free, sink, eo, po);
    mine.rays = 1;
  }
  WarpAddExposure(eo, out);
  if constexpr (kPoses) WarpAddExposure(po, out);
  WriteBlockStats(mine, partials);
}

// Thread j evaluates ray offset + j stride of `count` such rays.
__global__ void __launch_bounds__(kRayThreads) CostKernel(PassInput in, int64_t stride, int64_t offset,
                                                          int64_t count, RayStats* partials) {
  const int64_t j = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  RayStats mine;
  if (j < count) {
    const int64_t i = offset + j * stride;
    const TrainingRay r = MakeRay(in, i);
    float target[3];
    TargetOf(in.rays, i, target);
    mine = StatsOf(Forward(in.vol, r.ray, r.jit, target, in.lambda, in.stop_transmittance, nullptr,
                           AlphaOf(in.rays, i), TransformOfRay(in.rays, in.vol, i)),
                   in.robust);
  }
  WriteBlockStats(mine, partials);
}

// The CPU backend's Render, pixel by pixel: no jitter, the render rule (training_ray.h RulePixel).
// Rows y0 .. y0 + rows - 1; the outputs start at row y0.
__global__ void RenderKernel(VolumeView<float> vol, BoxFrame<float> box, PinholeCamera<float> camera, int width,
                             int y0, int rows, float stop, float min_box_opacity, float* colour, float* opacity) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, row = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= width || row >= rows) return;
  const int y = y0 + row;
  const Jitter none{0, 0, false, false};
  const float zero[3] = {0, 0, 0};
  const BoxRay<float> ray = PixelBoxRay(camera, box, vol.n, x, y, none);
  const RayOutput<float> o = Forward(vol, ray, none, zero, 0.f, stop);
  const int64_t i = static_cast<int64_t>(row) * width + x;
  RulePixel(o, min_box_opacity, &colour[3 * i], &opacity[i]);
}

// Sums the per-block partials in a fixed order and returns the total (synchronises).
RayStats Total(const StatsScratch& s, int64_t blocks) {
  RayStats total;
  if (blocks == 0) return total;
  PERF_CHECK(blocks <= s.capacity);
  size_t bytes = s.temp_bytes;
  PERF_CUDA_CHECK(cub::DeviceReduce::Reduce(s.temp, bytes, s.partials, s.total, blocks, SumStats{}, RayStats{}));
  PERF_CUDA_CHECK(cudaMemcpy(&total, s.total, sizeof(RayStats), cudaMemcpyDeviceToHost));
  return total;
}

unsigned GridFor(int64_t blocks) {
  PERF_CHECK_MSG(blocks < (int64_t{1} << 31), blocks, " blocks of rays");
  return static_cast<unsigned>(blocks);
}

}  // namespace

const char* KernelImageError() {
  cudaFuncAttributes attr;
  const cudaError_t e = cudaFuncGetAttributes(&attr, RenderKernel);
  if (e == cudaSuccess) return nullptr;
  cudaGetLastError();  // not sticky: clear it
  return cudaGetErrorString(e);
}

int64_t KernelLocalMemoryBytes() {
  size_t per_thread = 0;
  PERF_CUDA_CHECK(cudaDeviceGetLimit(&per_thread, cudaLimitStackSize));
  auto at_least = [&](const void* kernel) {
    cudaFuncAttributes attr;
    PERF_CUDA_CHECK(cudaFuncGetAttributes(&attr, kernel));
    per_thread = std::max(per_thread, attr.localSizeBytes);
  };
  at_least(reinterpret_cast<const void*>(LinearizeKernel<true, false>));
  at_least(reinterpret_cast<const void*>(LinearizeKernel<false, false>));
  at_least(reinterpret_cast<const void*>(LinearizeKernel<true, true>));
  at_least(reinterpret_cast<const void*>(LinearizeKernel<false, true>));
  at_least(reinterpret_cast<const void*>(JtJpKernel<false>));
  at_least(reinterpret_cast<const void*>(JtJpKernel<true>));
  at_least(reinterpret_cast<const void*>(JtJpRecordKernel<false>));
  at_least(reinterpret_cast<const void*>(JtJpRecordKernel<true>));
  at_least(reinterpret_cast<const void*>(CostKernel));
  at_least(reinterpret_cast<const void*>(RenderKernel));
  int device = 0, sms = 0, threads = 0;
  PERF_CUDA_CHECK(cudaGetDevice(&device));
  PERF_CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  PERF_CUDA_CHECK(cudaDeviceGetAttribute(&threads, cudaDevAttrMaxThreadsPerMultiProcessor, device));
  return static_cast<int64_t>(per_thread) * sms * threads;
}

int64_t PassBlocks(int64_t rays) { return (rays + kRayThreads - 1) / kRayThreads; }
// The rays offset, offset + stride, ... of the pass's `rays` (one thread each).
int64_t SubsetRays(int64_t rays, int stride, int offset) {
  PERF_CHECK(stride >= 1 && offset >= 0 && offset < stride);
  return rays > offset ? (rays - offset + stride - 1) / stride : 0;
}

size_t StatsTempBytes(int64_t blocks) {
  size_t bytes = 0;
  PERF_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, bytes, static_cast<RayStats*>(nullptr),
                                            static_cast<RayStats*>(nullptr), std::max<int64_t>(blocks, 1), SumStats{},
                                            RayStats{}));
  return bytes;
}

RayStats Linearize(const PassInput& in, float* g, float* diag, float* pose_blocks, const RecordView& rec,
                   int64_t params, int stride, int offset, const StatsScratch& s) {
  PERF_CUDA_CHECK(cudaMemset(g, 0, params * sizeof(float)));
  if (diag) PERF_CUDA_CHECK(cudaMemset(diag, 0, params * sizeof(float)));
  const bool poses = in.rays.pose_slot != nullptr;
  PERF_CHECK(!(poses && diag) || pose_blocks != nullptr);
  PERF_CHECK(rec.heads == nullptr || (diag != nullptr && rec.used != nullptr && rec.stride >= 1 &&
                                      rec.offset >= 0 && rec.offset < rec.stride));
  if (poses && diag) {
    PERF_CUDA_CHECK(cudaMemset(pose_blocks, 0, static_cast<size_t>(in.vol.poses) * kPoseBlock * sizeof(float)));
  }
  if (rec.heads) PERF_CUDA_CHECK(cudaMemset(rec.used, 0, sizeof(unsigned long long)));
  const int64_t blocks = PassBlocks(in.rays.count);
  if (blocks == 0) return {};
  PERF_CHECK(blocks <= s.capacity);
  if (diag && poses) {
    LinearizeKernel<true, true>
        <<<GridFor(blocks), kRayThreads>>>(in, g, diag, pose_blocks, rec, stride, offset, s.partials);
  } else if (diag) {
    LinearizeKernel<true, false><<<GridFor(blocks), kRayThreads>>>(in, g, diag, nullptr, rec, stride, offset, s.partials);
  } else if (poses) {
    LinearizeKernel<false, true>
        <<<GridFor(blocks), kRayThreads>>>(in, g, nullptr, nullptr, RecordView{}, stride, offset, s.partials);
  } else {
    LinearizeKernel<false, false>
        <<<GridFor(blocks), kRayThreads>>>(in, g, nullptr, nullptr, RecordView{}, stride, offset, s.partials);
  }
  PERF_CUDA_CHECK_LAUNCH("LinearizeKernel");
  return Total(s, blocks);
}

int64_t RecordedEntries(const RecordView& rec) {
  if (!rec.heads) return 0;
  unsigned long long used = 0;
  PERF_CUDA_CHECK(cudaMemcpy(&used, rec.used, sizeof(used), cudaMemcpyDeviceToHost));
  return static_cast<int64_t>(used);
}

RayStats MultiplyJtJ(const PassInput& in, const float* p, const float* free, float* out, int64_t params, int stride,
                     int offset, const StatsScratch& s, const RecordView& rec, bool recompute_rest) {
  const int64_t count = SubsetRays(in.rays.count, stride, offset);
  PERF_CUDA_CHECK(cudaMemset(out, 0, params * sizeof(float)));
  const int64_t blocks = PassBlocks(count);
  if (blocks == 0) return {};
  PERF_CHECK(blocks <= s.capacity);
  const bool poses = in.rays.pose_slot != nullptr;
  RayStats total;
  if (rec.heads) {
    PERF_CHECK(rec.stride == stride && rec.offset == offset);
    if (poses) {
      JtJpRecordKernel<true><<<GridFor(blocks), kRayThreads>>>(in, rec, p, free, out, count, s.partials);
    } else {
      JtJpRecordKernel<false><<<GridFor(blocks), kRayThreads>>>(in, rec, p, free, out, count, s.partials);
    }
    PERF_CUDA_CHECK_LAUNCH("JtJpRecordKernel");
    total = Total(s, blocks);
    if (!recompute_rest) return total;
  }
  const RayRecordHead* recorded = rec.heads;
  if (poses) {
    JtJpKernel<true><<<GridFor(blocks), kRayThreads>>>(in, p, free, out, stride, offset, count, recorded, s.partials);
  } else {
    JtJpKernel<false><<<GridFor(blocks), kRayThreads>>>(in, p, free, out, stride, offset, count, recorded, s.partials);
  }
  PERF_CUDA_CHECK_LAUNCH("JtJpKernel");
  const RayStats rest = Total(s, blocks);
  return SumStats{}(total, rest);
}

RayStats Cost(const PassInput& in, int stride, int offset, const StatsScratch& s) {
  const int64_t count = SubsetRays(in.rays.count, stride, offset);
  const int64_t blocks = PassBlocks(count);
  if (blocks == 0) return {};
  PERF_CHECK(blocks <= s.capacity);
  CostKernel<<<GridFor(blocks), kRayThreads>>>(in, stride, offset, count, s.partials);
  PERF_CUDA_CHECK_LAUNCH("CostKernel");
  return Total(s, blocks);
}

void Render(const VolumeView<float>& vol, const BoxFrame<float>& box, const PinholeCamera<float>& camera, int width,
            int y0, int rows, float stop_transmittance, float min_box_opacity, float* colour, float* opacity) {
  if (width <= 0 || rows <= 0) return;
  const dim3 block(16, 8);
  const dim3 grid((width + block.x - 1) / block.x, (rows + block.y - 1) / block.y);
  RenderKernel<<<grid, block>>>(vol, box, camera, width, y0, rows, stop_transmittance, min_box_opacity, colour,
                                opacity);
  PERF_CUDA_CHECK_LAUNCH("RenderKernel");
}

}  // namespace perf::recon::cuda
