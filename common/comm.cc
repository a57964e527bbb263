#include "common/comm.h"

#include <algorithm>
#include <cstdlib>
#include <string_view>
#include <vector>

namespace perf {

bool Communicator::Any(bool mine) {
  double v[1] = {mine ? 1.0 : 0.0};
  MaxInPlace(v);
  return v[0] > 0;
}

bool Communicator::Agree(double mine) {
  double v[2] = {mine, -mine};  // max(x) == -max(-x) == min(x) when every rank has the same x
  MaxInPlace(v);
  return v[0] == -v[1];
}

Communicator::Share Communicator::ShareOf(long long mine) {
  std::vector<double> counts(static_cast<size_t>(size()), 0.0);
  counts[static_cast<size_t>(rank())] = static_cast<double>(mine);  // exact below 2^53
  SumInPlace(counts);
  Share s;
  for (int r = 0; r < size(); ++r) {
    if (r < rank()) s.first += static_cast<long long>(counts[r]);
    s.total += static_cast<long long>(counts[r]);
  }
  return s;
}

bool LaunchedByMpi() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS", "SLURM_PROCID"}) {
    if (std::getenv(v) != nullptr) {
      // Slurm sets SLURM_PROCID for every job step, MPI or not: only with a PMI layer.
      if (std::string_view(v) == "SLURM_PROCID" && std::getenv("PMI_FD") == nullptr) continue;
      return true;
    }
  }
  return false;
}

int LocalRank() {
  for (const char* v : {"OMPI_COMM_WORLD_LOCAL_RANK", "SLURM_LOCALID", "MPI_LOCALRANKID", "PMI_LOCAL_RANK"}) {
    if (const char* s = std::getenv(v)) return std::max(0, std::atoi(s));
  }
  return 0;
}

IndexRange ContiguousShare(std::span<const double> weights, int rank, int size) {
  const size_t n = weights.size();
  if (size <= 1) return {0, n};
  std::vector<double> prefix(n + 1, 0.0);
  for (size_t i = 0; i < n; ++i) prefix[i + 1] = prefix[i] + std::max(0.0, weights[i]);
  // Boundary r: the first item whose prefix weight reaches r/size of the total, kept so that
  // every block holds at least one item when there are enough.
  const auto boundary = [&](int r) -> size_t {
    if (r <= 0) return 0;
    if (r >= size) return n;
    const double target = prefix[n] * r / size;
    size_t b = static_cast<size_t>(std::lower_bound(prefix.begin(), prefix.end(), target) - prefix.begin());
    if (n >= static_cast<size_t>(size)) b = std::clamp(b, static_cast<size_t>(r), n - static_cast<size_t>(size - r));
    return std::min(b, n);
  };
  return {boundary(rank), boundary(rank + 1)};  // boundaries never decrease with r
}

}  // namespace perf
