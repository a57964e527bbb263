// Checking CUDA runtime calls (STYLE.md "Host and device"): every call goes through
// PERF_CUDA_CHECK, which throws perf's error types naming the call, the CUDA error and the source
// location. Out of device memory is a ResourceError (the user can pick a smaller level or device);
// anything else is an InternalError (a bug, a broken driver or a kernel fault).
// A reported error is cleared from the runtime's last error (cudaGetLastError), so that the next
// launch check does not blame an unrelated kernel for it (sticky errors cannot be cleared).
// Host code only (g++ or nvcc's host pass); never used in destructors, which must not throw.
#pragma once

#include <cuda_runtime_api.h>

namespace perf::recon::cuda {

[[noreturn]] void ThrowCudaError(cudaError_t error, const char* call, const char* file, int line);

inline void CheckCuda(cudaError_t error, const char* call, const char* file, int line) {
  if (error != cudaSuccess) ThrowCudaError(error, call, file, line);
}

}  // namespace perf::recon::cuda

#define PERF_CUDA_CHECK(call) ::perf::recon::cuda::CheckCuda((call), #call, __FILE__, __LINE__)

// After a kernel launch: launch-configuration errors now, and (asynchronous) faults of earlier
// work at the latest at the next synchronising call, which is checked too.
#define PERF_CUDA_CHECK_LAUNCH(what) ::perf::recon::cuda::CheckCuda(cudaGetLastError(), what, __FILE__, __LINE__)
