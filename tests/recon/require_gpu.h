// GPU tests and PERF_REQUIRE_GPU (STYLE.md "Tests"): where no CUDA device is usable a GPU test
// skips with the reason (CI, laptops), unless the run says a GPU is required: with
// PERF_REQUIRE_GPU set to anything but "" or "0" (bench/gpu_check.sh sets it) the same case is a
// failure with the reason (driver not found, no device, wrong arch), so that a run on a GPU
// machine whose device is not seen cannot read as a pass.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>

namespace perf::test {

inline bool GpuRequired() {
  const char* v = std::getenv("PERF_REQUIRE_GPU");
  return v != nullptr && *v != '\0' && std::strcmp(v, "0") != 0;
}

}  // namespace perf::test

// In SetUp or a test body: when `available` is false, skips (or, with PERF_REQUIRE_GPU, fails)
// and returns, naming `reason`.
#define PERF_SKIP_OR_FAIL_WITHOUT_GPU(available, reason)                                                   \
  do {                                                                                                     \
    if (!(available)) {                                                                                    \
      if (::perf::test::GpuRequired()) {                                                                   \
        FAIL() << "no CUDA device: " << (reason) << " (PERF_REQUIRE_GPU is set, so this is a failure)";    \
      } else {                                                                                             \
        GTEST_SKIP() << "no CUDA device: " << (reason) << " (PERF_REQUIRE_GPU=1 makes this a failure)";    \
      }                                                                                                    \
    }                                                                                                      \
  } while (0)
