#include "common/system_memory.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>

#include "common/errors.h"

namespace perf {

namespace {

// MemAvailable of /proc/meminfo (bytes), 0 if unknown.
int64_t MachineAvailable() {
  std::ifstream in("/proc/meminfo");
  std::string key, unit;
  int64_t value = 0;
  while (in >> key >> value >> unit) {
    if (key == "MemAvailable:") return value * 1024;
  }
  return 0;
}

// What this process's cgroup (v2) still allows: memory.max - memory.current; 0 if unlimited or unknown.
int64_t CgroupAvailable() {
  std::ifstream cgroup("/proc/self/cgroup");
  std::string line;
  while (std::getline(cgroup, line)) {
    if (line.rfind("0::", 0) != 0) continue;
    const std::string dir = "/sys/fs/cgroup" + line.substr(3);
    std::ifstream max_in(dir + "/memory.max"), current_in(dir + "/memory.current");
    std::string max_text;
    int64_t current = 0;
    if (!(max_in >> max_text) || max_text == "max" || !(current_in >> current)) return 0;
    const int64_t max = std::strtoll(max_text.c_str(), nullptr, 10);
    return max > 0 ? std::max<int64_t>(1, max - current) : 0;
  }
  return 0;
}

// What the address-space limit (ulimit -v) still allows beyond what this process maps; 0 if unlimited.
int64_t AddressSpaceAvailable() {
  rlimit limit{};
  if (::getrlimit(RLIMIT_AS, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return 0;
  std::ifstream statm("/proc/self/statm");
  int64_t pages = 0;
  statm >> pages;
  const int64_t mapped = pages * ::sysconf(_SC_PAGESIZE);
  return std::max<int64_t>(1, static_cast<int64_t>(limit.rlim_cur) - mapped);
}

}  // namespace

int64_t AvailableMemory() {
  int64_t available = 0;
  for (const int64_t bound : {MachineAvailable(), CgroupAvailable(), AddressSpaceAvailable()}) {
    if (bound > 0) available = available > 0 ? std::min(available, bound) : bound;
  }
  return available;
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
