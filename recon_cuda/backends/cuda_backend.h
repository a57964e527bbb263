// The CUDA backend (DESIGN.md "Backends"): the passes of backend.h as kernels that call the same
// per-ray code as the CPU backend (cuda_passes.cu), PCG's vector operations on the device
// (cuda_vector_ops.cu), and the memory of a level checked against the free device memory before
// anything is allocated. Built only when nvcc is found (PERF_WITH_CUDA); no CUDA types here.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "recon_cuda/solve/backend.h"

namespace perf::recon {

struct CudaBackendOptions {
  int device = 0;  // CUDA device ordinal (modulo the devices there are: one rank per GPU of a node)
  // Device memory the backend may use; 0: what cudaMemGetInfo reports free (plus what this
  // backend already holds) less 5 %.
  int64_t max_memory = 0;
  // MultiplyJtJ reads the partials that Linearize recorded (ray_record.h, 9 bytes a sample) where
  // they fit in the device memory the level leaves, and recomputes the rays that find no room;
  // false: every product recomputes every ray (three marches of it). Default true.
  bool record_jacobian = true;
};

// Throws ResourceError when no device is usable (CudaDeviceAvailable says why).
std::unique_ptr<Backend> MakeCudaBackend(const CudaBackendOptions& options);

// Device memory in use on the current device, by any process (total - free), bytes.
int64_t CudaMemoryInUse();

// The CUDA side of CudaDeviceAvailable (backend.h): device 0's name, or why there is none.
bool ProbeCudaDevice(std::string* name, std::string* reason);

}  // namespace perf::recon
