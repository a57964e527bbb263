// One mapping for a level's Jacobian record, in transparent huge pages, from which each block's
// record vector takes the room it reserves (cpu_jacobian_record.h BlockJ::cells). A first touch of
// 4 KiB pages costs about 2.4 s a GiB on the 2-core VM measured, 0.6 s with 2 MiB pages (docs/
// tuning.md "The merged record on lego 200's fine levels"). Per-block vectors in huge pages would
// keep up to 2 MiB each resident past their ends; in one region only the blocks' reserved room is
// resident (what the estimate gives beyond the cells, about 18 % on lego). Internal to the CPU backend.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <new>
#include <type_traits>
#include <vector>

namespace perf::recon::cpu {

class RecordArena {
 public:
  RecordArena() = default;
  RecordArena(const RecordArena&) = delete;
  RecordArena& operator=(const RecordArena&) = delete;
  ~RecordArena() { Release(); }

  // Room for `bytes` (rounded up to 2 MiB) of address space, asking for huge pages; pages become
  // resident where they are written. The mapping before is reused (its resident pages need no
  // first touch again), trimmed or grown: nothing may still hold room in it. Where the mapping
  // fails the arena stays empty and Take hands out nothing (0 bytes: the mapping is given back).
  void Reset(size_t bytes);
  void Release();
  // `bytes` of the mapping (aligned to 64), or nullptr once it is used up. Thread-safe.
  void* Take(size_t bytes);
  // What a Take of `bytes` uses of the arena.
  static size_t Rounded(size_t bytes) { return (bytes + kAlign - 1) / kAlign * kAlign; }
  bool Owns(const void* p) const {
    const auto* b = static_cast<const std::byte*>(p);
    return base_ != nullptr && b >= base_ && b < base_ + size_;
  }
  size_t size() const { return size_; }
  size_t used() const { return std::min(used_.load(std::memory_order_relaxed), size_); }

 private:
  static constexpr size_t kAlign = 64;  // a cache line: no two blocks' records share one
  std::byte* base_ = nullptr;
  size_t size_ = 0;
  std::atomic<size_t> used_{0};
};

// A std::vector allocator that takes from a RecordArena (none: the heap), and from the heap when
// the arena is used up. Room taken from the arena is given back only with the whole arena.
template <class T>
struct ArenaAllocator {
  using value_type = T;
  using propagate_on_container_copy_assignment = std::true_type;
  using propagate_on_container_move_assignment = std::true_type;
  using propagate_on_container_swap = std::true_type;

  RecordArena* arena = nullptr;

  ArenaAllocator() = default;
  explicit ArenaAllocator(RecordArena* a) : arena(a) {}
  template <class U>
  ArenaAllocator(const ArenaAllocator<U>& o) : arena(o.arena) {}  // NOLINT: rebinding

  T* allocate(size_t n) {
    if (void* p = arena ? arena->Take(n * sizeof(T)) : nullptr) return static_cast<T*>(p);
    return static_cast<T*>(::operator new(n * sizeof(T)));
  }
  void deallocate(T* p, size_t) {
    if (arena == nullptr || !arena->Owns(p)) ::operator delete(p);
  }
  template <class U>
  bool operator==(const ArenaAllocator<U>& o) const {
    return arena == o.arena;
  }
};

template <class T>
using ArenaVector = std::vector<T, ArenaAllocator<T>>;

}  // namespace perf::recon::cpu
