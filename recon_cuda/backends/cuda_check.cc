#include "recon_cuda/backends/cuda_check.h"

#include "common/errors.h"

namespace perf::recon::cuda {

void ThrowCudaError(cudaError_t error, const char* call, const char* file, int line) {
  // A failed call also leaves its error as the runtime's last error; a non-sticky one (out of
  // memory, a bad argument) would otherwise be reported again by the next launch check, against
  // an unrelated kernel. Clear it (sticky errors stay, and every later call reports them).
  cudaGetLastError();
  const std::string what = StrCat(call, " failed at ", file, ":", line, ": ", cudaGetErrorName(error), " (",
                                  cudaGetErrorString(error), ")");
  if (error == cudaErrorMemoryAllocation) {
    throw ResourceError(StrCat("out of GPU memory: ", what,
                               "; use fewer --levels or a larger --downscale, or free the GPU of other work"));
  }
  throw InternalError(StrCat("CUDA error: ", what));
}

}  // namespace perf::recon::cuda
