// perf_bench_cpu --levels: the hierarchy of perf reconstruct run sparse and dense on one
// workspace, one table per mode and level (stored cells and bricks, samples per ray, seconds per
// GN iteration and per pass, memory, held-out PSNR), and the ratios between the two.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "recon_cuda/data/occupancy.h"

namespace perf::bench {

struct CpuHierarchySettings {
  std::string workspace;
  int levels = 2, start = 32, iterations = 10, threads = 0;
  bool dense = true, sparse = true;  // which modes to run
  recon::OccupancyOptions occupancy;
};

// Prints the tables and returns them as JSON.
nlohmann::json RunCpuHierarchy(const CpuHierarchySettings& settings);

}  // namespace perf::bench
