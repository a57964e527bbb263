// Wall-clock seconds for the per-phase timings that solver summaries and logs report.
#pragma once

#include <chrono>

namespace perf {

using WallClock = std::chrono::steady_clock;

inline double SecondsSince(WallClock::time_point start) {
  return std::chrono::duration<double>(WallClock::now() - start).count();
}

}  // namespace perf
