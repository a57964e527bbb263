// Host/device annotation for the per-ray math: the same headers compile into the CPU backend,
// the CUDA kernels and the tests (STYLE.md "Host and device").
#pragma once

#ifdef __CUDACC__
#define PERF_HD __host__ __device__
#else
#define PERF_HD
#endif

#define PERF_HD_INLINE PERF_HD inline
