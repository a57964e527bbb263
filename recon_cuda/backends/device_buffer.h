// GPU memory with one owner (STYLE.md "Host and device"): DeviceBuffer<T> is a move-only RAII
// array in linear device memory with explicit, size-checked host copies; kernels get a plain
// pointer (or a view struct of pointers and sizes) and never own anything. Host code only.
#pragma once

#include <cstdint>
#include <span>
#include <utility>

#include "common/errors.h"
#include "recon_cuda/backends/cuda_check.h"

namespace perf::recon::cuda {

template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(int64_t count) : count_(count) {
    PERF_CHECK(count >= 0);
    if (count > 0) PERF_CUDA_CHECK(cudaMalloc(reinterpret_cast<void**>(&data_), Bytes()));
  }
  ~DeviceBuffer() {
    if (data_) cudaFree(data_);  // no throw from a destructor; a failure here is a sticky error the next call reports
  }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept : data_(std::exchange(o.data_, nullptr)), count_(std::exchange(o.count_, 0)) {}
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      if (data_) cudaFree(data_);
      data_ = std::exchange(o.data_, nullptr);
      count_ = std::exchange(o.count_, 0);
    }
    return *this;
  }

  T* data() { return data_; }
  const T* data() const { return data_; }
  int64_t size() const { return count_; }
  size_t Bytes() const { return static_cast<size_t>(count_) * sizeof(T); }

  void CopyFromHost(std::span<const T> host) {
    PERF_CHECK_MSG(static_cast<int64_t>(host.size()) == count_, "host ", host.size(), " vs device ", count_);
    if (count_ > 0) PERF_CUDA_CHECK(cudaMemcpy(data_, host.data(), Bytes(), cudaMemcpyHostToDevice));
  }
  void CopyToHost(std::span<T> host) const {
    PERF_CHECK_MSG(static_cast<int64_t>(host.size()) == count_, "host ", host.size(), " vs device ", count_);
    if (count_ > 0) PERF_CUDA_CHECK(cudaMemcpy(host.data(), data_, Bytes(), cudaMemcpyDeviceToHost));
  }
  // The first host.size() elements (at most size()).
  void CopyPrefixToHost(std::span<T> host) const {
    PERF_CHECK_MSG(static_cast<int64_t>(host.size()) <= count_, "host ", host.size(), " vs device ", count_);
    if (!host.empty()) {
      PERF_CUDA_CHECK(cudaMemcpy(host.data(), data_, host.size() * sizeof(T), cudaMemcpyDeviceToHost));
    }
  }

 private:
  T* data_ = nullptr;
  int64_t count_ = 0;
};

}  // namespace perf::recon::cuda
