// The CUDA device as the process finds it: whether one is usable (and why not), and the memory in
// use on it (cuda_backend.h). Host code.
#include <cuda_runtime_api.h>

#include <cstdlib>
#include <string>

#include "common/errors.h"
#include "recon_cuda/backends/cuda_backend.h"
#include "recon_cuda/backends/cuda_check.h"
#include "recon_cuda/backends/cuda_kernels.h"

namespace perf::recon {

int64_t CudaMemoryInUse() {
  size_t free = 0, total = 0;
  PERF_CUDA_CHECK(cudaMemGetInfo(&free, &total));
  return static_cast<int64_t>(total) - static_cast<int64_t>(free);
}

namespace {

// Why cudaGetDeviceCount failed, in the three cases a user can act on: no driver (or one too old
// for this runtime), no device visible, anything else with CUDA's own words.
std::string NoDeviceReason(cudaError_t e) {
  const std::string cuda = StrCat(cudaGetErrorString(e), " (", cudaGetErrorName(e), ")");
  switch (e) {
    case cudaErrorInsufficientDriver:
      return StrCat("driver not found: no NVIDIA driver (libcuda.so.1) was loaded, or it is older than this CUDA "
                    "runtime; ",
                    cuda, "; check nvidia-smi, and that LD_LIBRARY_PATH still contains the driver's folder");
    case cudaErrorNoDevice: {
      const char* visible = std::getenv("CUDA_VISIBLE_DEVICES");
      return StrCat("no device: the driver sees no CUDA device; ", cuda,
                    visible ? StrCat("; CUDA_VISIBLE_DEVICES=\"", visible, "\"") : std::string());
    }
    default:
      return StrCat("the CUDA runtime cannot use the driver: ", cuda);
  }
}

}  // namespace

bool ProbeCudaDevice(std::string* name, std::string* reason) {
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess) {
    cudaGetLastError();
    if (reason) *reason = NoDeviceReason(e);
    return false;
  }
  if (count == 0) {
    if (reason) *reason = NoDeviceReason(cudaErrorNoDevice);
    return false;
  }
  cudaDeviceProp prop;
  const cudaError_t p = cudaGetDeviceProperties(&prop, 0);
  if (p != cudaSuccess) {
    cudaGetLastError();
    if (reason) *reason = StrCat("cudaGetDeviceProperties: ", cudaGetErrorString(p));
    return false;
  }
  // Device 0 is the current device unless this process chose another; the kernels' image must
  // load on it (this build: sm_90 code + PTX, so not on GPUs before Hopper).
  if (const char* k = cuda::KernelImageError()) {
    if (reason) {
      *reason = StrCat("wrong arch: ", prop.name, " (compute capability ", prop.major, ".", prop.minor,
                       ") cannot run this build's kernels, built for sm_90 and newer (", k, ")");
    }
    return false;
  }
  if (name) *name = prop.name;
  return true;
}

}  // namespace perf::recon
