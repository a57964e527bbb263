#include "recon_cuda/backends/make_backend.h"

#include "common/errors.h"
#include "recon_cuda/backends/cpu_backend.h"
#ifdef PERF_WITH_CUDA
#include "recon_cuda/backends/cuda_backend.h"
#endif

namespace perf::recon {

bool CudaDeviceAvailable(std::string* name, std::string* reason) {
#ifdef PERF_WITH_CUDA
  return ProbeCudaDevice(name, reason);
#else
  (void)name;
  if (reason) *reason = "this build of perf has no CUDA backend (nvcc was not found when it was configured)";
  return false;
#endif
}

std::unique_ptr<Backend> MakeBackend(DeviceChoice device, int threads, int cuda_device) {
  if (device != DeviceChoice::kCpu) {
    std::string reason;
    if (CudaDeviceAvailable(nullptr, &reason)) {
#ifdef PERF_WITH_CUDA
      CudaBackendOptions o;
      o.device = cuda_device;
      return MakeCudaBackend(o);
#endif
    }
    if (device == DeviceChoice::kCuda) {
      throw ResourceError(StrCat("--device cuda: no CUDA device: ", reason,
                                 "; use --device cpu (or --device auto, which falls back to the CPU)"));
    }
  }
  CpuBackendOptions o;
  o.threads = threads;
  return MakeCpuBackend(o);
}

}  // namespace perf::recon
