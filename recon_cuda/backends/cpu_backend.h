// The CPU backend: the passes of backend.h with TBB threads over blocks of rays, calling the
// same per-ray code (ray_math.h, jacobian.h) as the CUDA kernels.
//
// Scatters go to per-thread buffers, summed after the pass (no atomics, no races). The cost is
// summed per fixed block of rays and then in block order, so it does not depend on the number
// of threads; g, diag and J^T J p are sums of per-thread buffers and agree to float rounding.
//
// Linearize records each ray's partials (per march sample: its position t and the 5 partials;
// per shell: the cube-map coordinate and 4 partials) when the level's memory allows it, so that
// every MultiplyJtJ of the iteration is a gather and a scatter with no exp and no forward sweep.
// Otherwise MultiplyJtJ recomputes them from x (which is why x must not change in between).
#pragma once

#include <memory>

#include "recon_cuda/solve/backend.h"

namespace perf::recon {

struct CpuBackendOptions {
  int threads = 0;  // 0: all cores; more than 8x the cores is refused (InputError)
  // Keep the Jacobian partials between passes when they fit (see above).
  bool cache_jacobian = true;
  // Keep it compact: each sample's partials in bfloat16 and its position as its march index,
  // 9 bytes instead of 24; J^T J p then within ~3e-3 of the exact product (docs/tuning.md).
  bool compact_jacobian = true;
  // With compact_jacobian, keep each ray's cells instead of its samples where the level has no
  // spherical harmonics and fits in half the memory with them: the samples' partials summed per
  // cell with their trilinear weights, in float (cpu_jacobian_record.h MergedCellJ), about 11x
  // the bytes; J^T J p then reads and writes each of a ray's cells once (docs/tuning.md).
  bool merged_jacobian = true;
  // Memory the backend may use; 0: what /proc/meminfo calls available, less 10 %.
  int64_t max_memory = 0;
};

std::unique_ptr<Backend> MakeCpuBackend(const CpuBackendOptions& options);

}  // namespace perf::recon
