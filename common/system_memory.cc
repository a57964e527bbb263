#include "common/system_memory.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <thread>

#include "common/errors.h"

namespace perf {

int64_t AvailableMemory() {
  std::ifstream in("/proc/meminfo");
  std::string key, unit;
  int64_t value = 0;
  while (in >> key >> value >> unit) {
    if (key == "MemAvailable:") return value * 1024;
  }
  return 0;
}

int CoreCount() { return static_cast<int>(std::max(1u, std::thread::hardware_concurrency())); }

std::string FormatByteCount(int64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double v = static_cast<double>(bytes);
  int u = 0;
  while (v >= 1024 && u < 4) {
    v /= 1024;
    ++u;
  }
  char buf[32];
  std::snprintf(buf, sizeof buf, u == 0 ? "%.0f %s" : "%.1f %s", v, units[u]);
  return buf;
}

void CheckFitsInMemory(int64_t bytes, const std::string& what, const std::string& hint) {
  const int64_t available = AvailableMemory();
  if (bytes < 0 || (available > 0 && bytes > available)) {
    throw ResourceError(StrCat("not enough memory: ", what, " needs ", FormatByteCount(bytes), ", ",
                               FormatByteCount(available), " available. ", hint));
  }
}

}  // namespace perf
