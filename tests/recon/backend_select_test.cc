// --device cpu|cuda|auto (MakeBackend), on any machine: without a usable CUDA device "cuda" is a
// clear ResourceError that says so and points to --device cpu, and "auto" falls back to the
// CPU; with one, "auto" picks it. Runs in CI without a GPU (label unit).
#include <gtest/gtest.h>

#include <string>

#include "common/errors.h"
#include "recon_cuda/backends/make_backend.h"

namespace perf::recon {
namespace {

TEST(BackendSelectTest, ProbingNeverThrows) {
  std::string name, reason;
  const bool available = CudaDeviceAvailable(&name, &reason);
  EXPECT_EQ(available, !name.empty()) << reason;
  EXPECT_EQ(available, reason.empty()) << reason;
  EXPECT_EQ(CudaDeviceAvailable(nullptr, nullptr), available);
}

TEST(BackendSelectTest, CudaWithoutADeviceIsAClearError) {
  std::string name, reason;
  if (CudaDeviceAvailable(&name, &reason)) GTEST_SKIP() << "a CUDA device is present (" << name << ")";
  try {
    MakeBackend(DeviceChoice::kCuda, 1);
    FAIL() << "expected ResourceError";
  } catch (const ResourceError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("no CUDA device"), std::string::npos) << what;
    EXPECT_NE(what.find(reason), std::string::npos) << what;
    EXPECT_NE(what.find("--device cpu"), std::string::npos) << what;
  }
}

TEST(BackendSelectTest, AutoPicksTheDeviceOrFallsBackToTheCpu) {
  std::string name;
  const bool cuda = CudaDeviceAvailable(&name, nullptr);
  const std::string d = MakeBackend(DeviceChoice::kAuto, 1)->Describe();
  if (cuda) {
    EXPECT_EQ(d, "cuda (" + name + ")");
  } else {
    EXPECT_EQ(d, "cpu (1 thread)");
  }
  EXPECT_EQ(MakeBackend(DeviceChoice::kCpu, 2)->Describe(), "cpu (2 threads)");
}

}  // namespace
}  // namespace perf::recon
