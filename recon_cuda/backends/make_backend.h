// The backend a command runs on (--device), made for it: the factory that knows both
// implementations, so that the Backend interface (solve/backend.h) includes neither.
#pragma once

#include <memory>
#include <string>

#include "recon_cuda/solve/backend.h"

namespace perf::recon {

// Which backend a command runs on (--device): kAuto is CUDA when a device is visible, else the CPU.
enum class DeviceChoice { kAuto, kCpu, kCuda };

// threads: CPU worker threads, 0 = all; cuda_device: the GPU (modulo the devices there are; a
// rank passes its rank on the node, comm.h LocalRank). kCuda without a usable device (or in a
// build without CUDA) throws ResourceError saying so.
std::unique_ptr<Backend> MakeBackend(DeviceChoice device, int threads, int cuda_device = 0);

// Whether the CUDA backend can run here: built with CUDA and a device visible to the runtime.
// Never throws and is safe without a driver. name: the device's name when true; reason: why not
// when false (either may be nullptr).
bool CudaDeviceAvailable(std::string* name, std::string* reason = nullptr);

}  // namespace perf::recon
