// The vector operations of PCG, line search and Adam on the device: element-wise kernels
// (grid-stride loops) and reductions in double with CUB's DeviceReduce, which sums in a fixed
// tree for a given size and device, so Dot and MaxAbs are reproducible run to run.
#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include <cub/device/device_reduce.cuh>

#include "common/errors.h"
#include "recon_cuda/backends/cuda_check.h"
#include "recon_cuda/backends/cuda_kernels.h"

namespace perf::recon::cuda {
namespace {

constexpr int kThreads = 256;

// Launches fn(i) for i in [0, n) on a grid-stride loop.
template <class Fn>
__global__ void __launch_bounds__(kThreads) ForEachKernel(int64_t n, Fn fn) {
  const int64_t stride = static_cast<int64_t>(gridDim.x) * blockDim.x;
  for (int64_t i = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x; i < n; i += stride) fn(i);
}

template <class Fn>
void ForEach(int64_t n, Fn fn, const char* what) {
  if (n <= 0) return;
  // Enough blocks to fill any current GPU several times; the loop covers the rest.
  const int64_t blocks = std::min<int64_t>((n + kThreads - 1) / kThreads, 65536);
  ForEachKernel<<<static_cast<unsigned>(blocks), kThreads>>>(n, fn);
  PERF_CUDA_CHECK_LAUNCH(what);
}

struct DotTerm {
  const float* a;
  const float* b;
  __device__ double operator()(int64_t i) const { return static_cast<double>(a[i]) * b[i]; }
};
struct AbsTerm {
  const float* a;
  __device__ double operator()(int64_t i) const { return static_cast<double>(fabsf(a[i])); }
};
struct SmoothnessTerm {
  SmoothnessLayout layout;
  SmoothnessWeights w;
  const float* v;
  __device__ double operator()(int64_t i) const {
    float lap, degree;
    return SmoothnessRow(layout, w, v, i, &lap, &degree);
  }
};
struct KindTerm {
  const float* v;
  ParamLayout layout;
  int kind;
  __device__ double operator()(int64_t i) const {
    return static_cast<int>(KindOfParam(layout, i)) == kind ? static_cast<double>(v[i]) : 0.0;
  }
};
struct AddD {
  __device__ double operator()(double x, double y) const { return x + y; }
};
struct MaxD {
  __device__ double operator()(double x, double y) const { return x < y ? y : x; }
};

template <class Term>
auto Terms(Term t) {
  return thrust::make_transform_iterator(thrust::counting_iterator<int64_t>(0), t);
}

template <class Term, class Op>
double Reduce(Term term, Op op, int64_t n, const ReduceScratch& s) {
  if (n <= 0) return 0;
  size_t bytes = s.temp_bytes;
  PERF_CUDA_CHECK(cub::DeviceReduce::Reduce(s.temp, bytes, Terms(term), s.result, n, op, 0.0));
  double r = 0;
  PERF_CUDA_CHECK(cudaMemcpy(&r, s.result, sizeof(double), cudaMemcpyDeviceToHost));
  return r;
}

}  // namespace

void Fill(float* y, int64_t n, float value) {
  ForEach(n, [=] __device__(int64_t i) { y[i] = value; }, "Fill");
}
void Copy(float* y, const float* x, int64_t n) {
  if (n > 0) PERF_CUDA_CHECK(cudaMemcpy(y, x, n * sizeof(float), cudaMemcpyDeviceToDevice));
}
void Axpy(float* y, float a, const float* x, int64_t n) {
  ForEach(n, [=] __device__(int64_t i) { y[i] += a * x[i]; }, "Axpy");
}
void Xpby(float* y, const float* x, float b, int64_t n) {
  ForEach(n, [=] __device__(int64_t i) { y[i] = x[i] + b * y[i]; }, "Xpby");
}
void DivideClamped(float* z, const float* r, const float* d, float floor, int64_t n) {
  ForEach(n, [=] __device__(int64_t i) { z[i] = r[i] / Max(d[i], floor); }, "DivideClamped");
}
void AxpyDiag(float* y, float a, const float* d, const float* x, int64_t n) {
  ForEach(n, [=] __device__(int64_t i) { y[i] += a * d[i] * x[i]; }, "AxpyDiag");
}
void Project(float* x, int64_t n, const ParamLayout& layout) {
  ForEach(n, [=] __device__(int64_t i) { x[i] = ProjectToValid(KindOfParam(layout, i), x[i]); }, "Project");
}
void HoldParameters(const float* x, float* g, float* free, int64_t n, const ParamLayout& layout,
                    const HeldKinds& held_kinds, bool bounds) {
  const HeldKinds kinds = held_kinds;
  ForEach(
      n,
      [=] __device__(int64_t i) {
        const bool held = HeldParameter(KindOfParam(layout, i), x[i], g[i], kinds, bounds);
        free[i] = held ? 0.f : 1.f;
        if (held) g[i] = 0.f;
      },
      "HoldParameters");
}
void Multiply(float* y, const float* m, int64_t n) {
  ForEach(n, [=] __device__(int64_t i) { y[i] *= m[i]; }, "Multiply");
}
void AdamStep(float* x, const float* g, float* m, float* v, const AdamCoefficients& c, int64_t n,
              const ParamLayout& layout) {
  ForEach(n, [=] __device__(int64_t i) { AdamUpdate(c, KindOfParam(layout, i), g[i], &x[i], &m[i], &v[i]); },
          "AdamStep");
  Project(x, n, layout);
}

size_t ReduceTempBytes(int64_t n) {
  size_t dot = 0, max = 0;
  n = std::max<int64_t>(n, 1);
  PERF_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, dot, Terms(DotTerm{}), static_cast<double*>(nullptr), n, AddD{},
                                            0.0));
  PERF_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, max, Terms(AbsTerm{}), static_cast<double*>(nullptr), n, MaxD{},
                                            0.0));
  size_t smooth = 0, kind = 0;
  PERF_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, smooth, Terms(SmoothnessTerm{}), static_cast<double*>(nullptr), n,
                                            AddD{}, 0.0));
  PERF_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, kind, Terms(KindTerm{}), static_cast<double*>(nullptr), n, AddD{},
                                            0.0));
  return std::max({dot, max, smooth, kind});
}

double Dot(const float* a, const float* b, int64_t n, const ReduceScratch& s) {
  return Reduce(DotTerm{a, b}, AddD{}, n, s);
}
double MaxAbs(const float* a, int64_t n, const ReduceScratch& s) { return Reduce(AbsTerm{a}, MaxD{}, n, s); }


void AddSmoothness(const float* v, const SmoothnessLayout& layout, const SmoothnessWeights& w, float* out, float* diag,
                   int64_t n) {
  if (out == nullptr && diag == nullptr) return;
  ForEach(
      n,
      [=] __device__(int64_t i) {
        float lap, degree;
        SmoothnessRow(layout, w, v, i, &lap, &degree);
        if (out != nullptr) out[i] += lap;
        if (diag != nullptr) diag[i] += degree;
      },
      "AddSmoothness");
}

double SmoothnessCost(const float* v, const SmoothnessLayout& layout, const SmoothnessWeights& w, int64_t n,
                      const ReduceScratch& s) {
  return Reduce(SmoothnessTerm{layout, w, v}, AddD{}, n, s);
}

std::array<double, kParamKinds> SumByKind(const float* v, int64_t n, const ParamLayout& layout,
                                          const ReduceScratch& s) {
  std::array<double, kParamKinds> sums{};
  for (int kind = 0; kind < kParamKinds; ++kind) {
    sums[kind] = Reduce(KindTerm{v, layout, kind}, AddD{}, n, s);
  }
  return sums;
}

}  // namespace perf::recon::cuda
