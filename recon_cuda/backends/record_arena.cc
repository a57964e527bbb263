#include "recon_cuda/backends/record_arena.h"

#include <sys/mman.h>

namespace perf::recon::cpu {
namespace {
constexpr size_t kHugePage = size_t{2} << 20;
}  // namespace

void RecordArena::Reset(size_t bytes) {
  const size_t size = (bytes + kHugePage - 1) / kHugePage * kHugePage;
  used_.store(0, std::memory_order_relaxed);
  if (size == 0) return Release();
  if (base_ != nullptr && size <= size_) {  // the pages kept, those past `size` given back
    if (size < size_) munmap(base_ + size, size_ - size);
    size_ = size;
    return;
  }
  constexpr int kFlags = MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE;
  void* p = base_ != nullptr ? mremap(base_, size_, size, MREMAP_MAYMOVE)
                             : mmap(nullptr, size, PROT_READ | PROT_WRITE, kFlags, -1, 0);
  if (p == MAP_FAILED) {  // the vectors take the heap instead
    Release();
    return;
  }
  // Advice only: where the kernel has no huge pages (THP off) the mapping keeps 4 KiB ones.
  madvise(p, size, MADV_HUGEPAGE);
  base_ = static_cast<std::byte*>(p);
  size_ = size;
}

void RecordArena::Release() {
  if (base_ != nullptr) munmap(base_, size_);
  base_ = nullptr;
  size_ = 0;
  used_.store(0, std::memory_order_relaxed);
}

void* RecordArena::Take(size_t bytes) {
  if (base_ == nullptr || bytes == 0) return nullptr;
  const size_t room = Rounded(bytes);
  const size_t at = used_.fetch_add(room, std::memory_order_relaxed);
  if (at + room > size_) return nullptr;  // used up (used_ stays past the end: later takes fail too)
  return base_ + at;
}

}  // namespace perf::recon::cpu
