#include "sfm_import/sfm_matching_time.h"

#include <algorithm>
#include <cmath>
#include <thread>

namespace perf {

namespace {

constexpr double kPairSecondsOn2Threads = 0.28;
constexpr double kSfmSecondsPerMegapixelOn2Threads = 11.6;

// How much faster than on 2 threads `o`'s threads run COLMAP (at most 16 count).
double ThreadSpeedup(const SfmOptions& o) {
  const int threads = o.num_threads > 0 ? o.num_threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  return std::min(threads, 16) / 2.0;
}

}  // namespace

double PairSeconds(const SfmOptions& o) { return kPairSecondsOn2Threads / ThreadSpeedup(o); }

double SequentialSfmSeconds(const SfmOptions& o, int photos, double megapixels) {
  return kSfmSecondsPerMegapixelOn2Threads * photos * megapixels / ThreadSpeedup(o);
}

int AutoExhaustiveMax(const SfmOptions& o) {
  if (!o.seconds_left) return o.exhaustive_max_images;
  const double pairs = std::max(0.0, 0.5 * o.seconds_left()) / PairSeconds(o);
  const int fits = static_cast<int>(std::floor(0.5 + std::sqrt(0.25 + 2.0 * pairs)));  // n (n - 1) / 2 <= pairs
  return std::min(o.exhaustive_max_images, fits);
}

double EveryPairSeconds(const SfmOptions& o, int n_photos, double match_seconds, double map_seconds) {
  const double n = n_photos, all = n * (n - 1) / 2;
  const double done = std::min(all, n * (o.sequential_overlap + std::floor(std::log2(std::max(2.0, n)))));
  return match_seconds * std::max(0.0, all - done) / std::max(1.0, done) + map_seconds;
}

}  // namespace perf
