// What the machine has to give: memory to check sizes against before allocating them, and cores.
#pragma once

#include <cstdint>
#include <string>

namespace perf {

// The memory this process may still take (bytes), 0 if unknown: the least of /proc/meminfo's
// MemAvailable, what its cgroup's memory.max leaves and what the address-space limit (ulimit -v)
// leaves, so that a size is refused before the allocation a limit would fail.
int64_t AvailableMemory();

// Throws ResourceError when `bytes` for `what` exceed the available memory (unknown: passes).
// `what` names the allocation in the message, e.g. "decoding photo.png (10000x10000)".
void CheckFitsInMemory(int64_t bytes, const std::string& what, const std::string& hint);

// This machine's cores (at least 1), and the most worker threads PERF accepts: 8 per core (more
// is a typo; TBB crashed destroying an arena of 100000).
int CoreCount();
inline int MaxWorkerThreads() { return 8 * CoreCount(); }

// "1.5 GiB"-style.
std::string FormatByteCount(int64_t bytes);

}  // namespace perf
