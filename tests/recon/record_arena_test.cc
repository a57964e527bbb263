// The CPU backend's record arena (record_arena.h): room handed out once, aligned and apart, from
// one mapping that a level's blocks share; vectors that outgrow it move to the heap; the mapping
// kept, trimmed or grown for the next level with what its pages hold.
#include "recon_cuda/backends/record_arena.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <thread>
#include <utility>
#include <vector>

namespace perf::recon::cpu {
namespace {

constexpr size_t kMiB = size_t{1} << 20;

TEST(RecordArenaTest, HandsOutAlignedRoomOnceUntilUsedUp) {
  RecordArena arena;
  EXPECT_EQ(arena.Take(100), nullptr) << "no mapping yet";
  arena.Reset(3 * kMiB);
  ASSERT_EQ(arena.size(), 4 * kMiB) << "rounded up to huge pages";
  void* a = arena.Take(100);
  void* b = arena.Take(1);
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(a) % 64, 0u);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(b) % 64, 0u);
  EXPECT_GE(static_cast<char*>(b) - static_cast<char*>(a), 100);
  EXPECT_TRUE(arena.Owns(a));
  int on_stack = 0;
  EXPECT_FALSE(arena.Owns(&on_stack));
  EXPECT_EQ(arena.Take(4 * kMiB), nullptr) << "more than is left";
  EXPECT_EQ(arena.Take(64), nullptr) << "used up: nothing after an overrun either";
  EXPECT_EQ(arena.used(), arena.size());
  arena.Reset(0);
  EXPECT_EQ(arena.size(), 0u);
  EXPECT_EQ(arena.Take(64), nullptr);
}

TEST(RecordArenaTest, ThreadsTakeDisjointRoom) {
  RecordArena arena;
  arena.Reset(8 * kMiB);
  std::vector<std::vector<std::pair<char*, size_t>>> got(4);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (size_t i = 0; i < 2000; ++i) {
        const size_t bytes = 1 + (i * 37 + t) % 700;
        if (void* p = arena.Take(bytes)) got[t].push_back({static_cast<char*>(p), bytes});
      }
    });
  }
  for (std::thread& th : threads) th.join();
  std::vector<std::pair<char*, size_t>> all;
  for (const auto& g : got) all.insert(all.end(), g.begin(), g.end());
  ASSERT_EQ(all.size(), 8000u) << "8 MiB holds every take";
  std::sort(all.begin(), all.end());
  for (size_t i = 1; i < all.size(); ++i) EXPECT_LE(all[i - 1].first + all[i - 1].second, all[i].first);
}

TEST(RecordArenaTest, VectorsTakeTheArenaThenTheHeap) {
  RecordArena arena;
  arena.Reset(2 * kMiB);
  ArenaVector<float> v{ArenaAllocator<float>(&arena)};
  v.reserve(1000);
  EXPECT_TRUE(arena.Owns(v.data())) << "its reserved room is the arena's";
  for (int i = 0; i < 1000; ++i) v.push_back(static_cast<float>(i));
  v.resize(kMiB);  // 4 MiB: past what the arena has left
  EXPECT_FALSE(arena.Owns(v.data())) << "outgrown: on the heap";
  for (int i = 0; i < 1000; ++i) ASSERT_EQ(v[i], static_cast<float>(i)) << "moved with its values";
  ArenaVector<float> plain;  // no arena: the heap only
  plain.assign(10, 1.f);
  EXPECT_FALSE(arena.Owns(plain.data()));
  v = std::move(plain);  // the heap room freed, the arena's left alone
  EXPECT_EQ(v.size(), 10u);
}

// A level's room reused for the next: trimmed or grown, the pages written before stay (no first
// touch again), and those past a trim are given back.
TEST(RecordArenaTest, ResetKeepsTheWrittenPages) {
  RecordArena arena;
  arena.Reset(6 * kMiB);
  auto* first = static_cast<uint32_t*>(arena.Take(kMiB));
  ASSERT_NE(first, nullptr);
  for (size_t i = 0; i < kMiB / 4; ++i) first[i] = static_cast<uint32_t>(i * 2654435761u);
  arena.Reset(2 * kMiB);
  EXPECT_EQ(arena.size(), 2 * kMiB);
  auto* again = static_cast<uint32_t*>(arena.Take(kMiB));
  ASSERT_EQ(again, first) << "the same mapping, from its start";
  arena.Reset(64 * kMiB);
  EXPECT_EQ(arena.size(), 64 * kMiB);
  auto* grown = static_cast<uint32_t*>(arena.Take(kMiB));
  ASSERT_NE(grown, nullptr);
  for (size_t i = 0; i < kMiB / 4; ++i) ASSERT_EQ(grown[i], static_cast<uint32_t>(i * 2654435761u)) << i;
  void* last = arena.Take(60 * kMiB);
  ASSERT_NE(last, nullptr) << "the grown room is there";
  static_cast<char*>(last)[60 * kMiB - 1] = 1;
}

}  // namespace
}  // namespace perf::recon::cpu
