// Host/device annotation for the per-ray math: the same headers compile into the CPU backend,
// the CUDA kernels and the tests (STYLE.md "Host and device").
#pragma once

#ifdef __CUDACC__
#define PERF_HD __host__ __device__
#else
#define PERF_HD
#endif

// Small per-sample functions are forced inline: they run tens of times per ray, and GCC's
// heuristics otherwise leave some (TrilinearWeights) as calls in the hot loops.
#if defined(__CUDACC__)
#define PERF_HD_INLINE __host__ __device__ __forceinline__
#elif defined(__GNUC__)
#define PERF_HD_INLINE inline __attribute__((always_inline))
#else
#define PERF_HD_INLINE inline
#endif
