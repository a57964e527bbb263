#include "recon_cuda/backend.h"

#include "common/errors.h"
#include "recon_cuda/cpu_backend.h"

namespace perf::recon {

std::unique_ptr<Backend> MakeBackend(const std::string& device, int threads) {
  if (device == "cpu" || device == "auto") {
    // "auto" is the CPU until the CUDA backend lands (issue 4): there are no CUDA passes yet.
    CpuBackendOptions o;
    o.threads = threads;
    return MakeCpuBackend(o);
  }
  if (device == "cuda") {
    throw InputError("command line", "--device", device,
                     "the CUDA backend of the solver is not implemented yet in this build",
                     "use --device cpu (or auto)");
  }
  throw InputError("command line", "--device", device, "unknown device", "use cpu, cuda or auto");
}

}  // namespace perf::recon
