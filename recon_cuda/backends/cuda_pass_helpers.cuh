// The device-side pieces the ray kernels of cuda_passes.cu share: the atomic sink of their
// scatters, the warp sums of a photo's exposure and pose entries, the per-block statistics, the
// ray of a pass and the Jacobian record's room. Included by cuda_passes.cu alone (device code,
// no separate compilation).
#pragma once

#include <cooperative_groups.h>
#include <cooperative_groups/scan.h>

#include <cub/block/block_reduce.cuh>

#include "recon_cuda/backends/cuda_kernels.h"
#include "recon_cuda/core/pose.h"
#include "recon_cuda/core/ray_record.h"
#include "recon_cuda/core/training_ray.h"

namespace perf::recon::cuda::pass {

namespace cg = cooperative_groups;

constexpr int kRayThreads = 128;  // threads per block of the ray kernels (register-heavy)

struct AtomicSink {
  float* a;
  __device__ __forceinline__ void Add4(int64_t i, float x, float y, float z, float w) {
#if __CUDA_ARCH__ >= 900
    atomicAdd(reinterpret_cast<float4*>(a + i), make_float4(x, y, z, w));
#else
    atomicAdd(a + i, x);
    atomicAdd(a + i + 1, y);
    atomicAdd(a + i + 2, z);
    atomicAdd(a + i + 3, w);
#endif
  }
};

// A ray's exposure entries (jacobian.h ScatterJtuExposure, AddDiagExposure), or its pose entries
// (pose.h ScatterJtuPose, AddDiagPose: as many), kept in registers until WarpAddExposure: base is
// the photo's first exposure (pose) parameter (-1: none).
// (A photo's pose block, pose.h AddPoseBlock, is a group of kPoseBlock values at base.)
static_assert(kPoseValues == kExposureValues && kPoseBlock % 4 == 0);
template <int N>
struct GroupSums {
  int64_t base = -1;
  float v[N] = {};
  __device__ __forceinline__ void Add4(int64_t i, float x, float y, float z, float w) {
    float* p = v + (i - base);
    p[0] += x;
    p[1] += y;
    p[2] += z;
    p[3] += w;
  }
};
using ExposureSums = GroupSums<kExposureValues>;

// Adds every lane's group sums to dst. Every ray of a photo adds to the same values, and a warp's
// rays are usually of one photo (the rays go photo by photo, tile by tile): then the warp sums
// them with shuffles and one lane adds, instead of 32 atomics on one address. Call from every
// lane of the warp (lanes without a ray pass base -1).
template <int N>
__device__ void WarpAddGroup(GroupSums<N>& e, float* dst) {
  constexpr unsigned kAll = 0xffffffffu;
  const long long first = __shfl_sync(kAll, static_cast<long long>(e.base), 0);
  if (__all_sync(kAll, e.base == first)) {
    if (first < 0) return;
    for (int k = 0; k < N; ++k)
      for (int offset = 16; offset > 0; offset >>= 1) e.v[k] += __shfl_down_sync(kAll, e.v[k], offset);
    if ((threadIdx.x & 31) != 0) return;
  } else if (e.base < 0) {
    return;
  }
  AtomicSink sink{dst};
  for (int k = 0; k < N; k += 4) sink.Add4(e.base + k, e.v[k], e.v[k + 1], e.v[k + 2], e.v[k + 3]);
}
__device__ inline void WarpAddExposure(ExposureSums& e, float* dst) { WarpAddGroup(e, dst); }

struct SumStats {
  __host__ __device__ __forceinline__ RayStats operator()(const RayStats& a, const RayStats& b) const {
    return {a.cost + b.cost, a.colour_sse + b.colour_sse, a.rays + b.rays, a.samples + b.samples,
            a.subset_cost + b.subset_cost};
  }
};

// The cost of one ray (training_ray.h CostOf, as the CPU backend sums it).
__device__ __forceinline__ RayStats StatsOf(const RayOutput<float>& o, float robust) {
  const RayCost c = CostOf(o, robust);
  return {c.cost, c.colour_sse, 1, o.count, 0.0};
}

__device__ __forceinline__ void WriteBlockStats(const RayStats& mine, RayStats* partials) {
  using BlockReduce = cub::BlockReduce<RayStats, kRayThreads>;
  __shared__ typename BlockReduce::TempStorage temp;
  const RayStats sum = BlockReduce(temp).Reduce(mine, SumStats{});
  if (threadIdx.x == 0) partials[blockIdx.x] = sum;
}

// Ray i as every pass of the iteration of in.seed sees it, its targets (training_ray.h).
__device__ __forceinline__ TrainingRay MakeRay(const PassInput& in, int64_t i) {
  return RayOf(in.rays, in.vol, in.box, i, in.seed, in.jitter, in.pixel_jitter);
}

// The first of `need` entries of the Jacobian record for the calling thread's ray, or -1 when
// they do not fit: handed out a warp at a time (the lanes that ask, with one atomic on the
// counter and their prefix sums; when the warp's entries do not all fit, none of its rays gets
// any). Call from the rays of rec's subset alone.
__device__ inline int64_t ReserveEntries(const RecordView& rec, uint32_t need) {
  const cg::coalesced_group lanes = cg::coalesced_threads();
  const unsigned long long before = cg::exclusive_scan(lanes, static_cast<unsigned long long>(need));
  const unsigned long long total = lanes.shfl(before + need, lanes.num_threads() - 1);
  unsigned long long base = 0;
  if (lanes.thread_rank() == 0) base = atomicAdd(rec.used, total);
  base = lanes.shfl(base, 0);
  return base + total <= static_cast<unsigned long long>(rec.capacity) ? static_cast<int64_t>(base + before) : -1;
}

}  // namespace perf::recon::cuda::pass
