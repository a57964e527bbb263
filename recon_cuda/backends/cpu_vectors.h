// The CPU backend's parameter vectors and the element-wise operations of backend.h on them
// (the CUDA side's cuda_vector_ops.cu). Work is split into fixed chunks and reductions combine
// the chunks in order, so every result is the same for any thread count.
#pragma once

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "recon_cuda/data/volume.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

class CpuVectors {
 public:
  explicit CpuVectors(int threads) : arena_(threads) {}

  // `count` vectors of `size` zeros (none: count 0).
  void Assign(int count, int64_t size);
  std::vector<float>& operator[](VecId v);
  const std::vector<float>& operator[](VecId v) const;
  // The arena the passes share with the vector operations.
  tbb::task_arena& arena() const { return arena_; }

  void Upload(VecId v, std::span<const float> host);
  void Download(VecId v, std::span<float> host) const;
  void Fill(VecId v, float value);
  void Copy(VecId dst, VecId src);
  void Axpy(VecId y, double a, VecId x);
  void Xpby(VecId y, VecId x, double b);
  void DivideClamped(VecId z, VecId r, VecId d, float floor);
  void AxpyDiag(VecId y, double a, VecId d, VecId x);
  void Multiply(VecId y, VecId m);
  double Dot(VecId a, VecId b) const;
  double MaxAbs(VecId v, int64_t count = -1) const;  // of the first `count` entries (-1: all)
  // The operations that know what each parameter is (param_ops.h).
  void Project(VecId x, const VolumeShape& shape);
  void HoldParameters(VecId x, VecId g, VecId free, const VolumeShape& shape, const HeldKinds& held, bool bounds);
  void AdamStep(VecId x, VecId g, VecId m, VecId v, const AdamSettings& s, int t, const VolumeShape& shape);
  void AddSmoothness(VecId v, const VolumeShape& shape, const SmoothnessWeights& w, VecId out, VecId diag);
  double SmoothnessCost(VecId v, const VolumeShape& shape, const SmoothnessWeights& w) const;
  std::array<double, kParamKinds> SumByKind(VecId v, const VolumeShape& shape) const;

  // fn(begin, end) over the vectors' elements, in parallel over fixed chunks.
  template <class Fn>
  void ForChunks(Fn&& fn) const {
    const int64_t n = size();
    arena_.execute([&] {
      tbb::parallel_for(int64_t{0}, (n + kChunk - 1) / kChunk,
                        [&](int64_t c) { fn(c * kChunk, std::min(n, (c + 1) * kChunk)); });
    });
  }

 private:
  static constexpr int64_t kChunk = 1 << 15;  // elements per task

  template <class Fn, class Combine>
  double ReduceChunks(Fn&& fn, Combine&& combine) const;
  int64_t size() const { return vectors_.empty() ? 0 : static_cast<int64_t>(vectors_.front().size()); }

  mutable tbb::task_arena arena_;
  std::vector<std::vector<float>> vectors_;
};

// out = the sum of `parts` (each ParamCount floats; none: zeros), in chunks of `vectors`.
void SumParts(const CpuVectors& vectors, const std::vector<const float*>& parts, float* out);

// g and diag = the sums of `parts` whose values interleave g and diag in groups of 4 (AddSink).
void SumInterleavedParts(const CpuVectors& vectors, const std::vector<const float*>& parts, float* g, float* diag);

}  // namespace perf::recon
