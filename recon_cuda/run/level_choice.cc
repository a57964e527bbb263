#include "recon_cuda/run/level_choice.h"

#include <cmath>

#include "common/errors.h"

namespace perf::recon {
namespace {

constexpr int kMaxLevels = 6;

// The fewest levels from `start` whose finest grid has at least `cells` across (kMaxLevels at most).
int LevelsReaching(double cells, int start) {
  int levels = 1;
  while (levels < kMaxLevels && (start << (levels - 1)) < cells) ++levels;
  return levels;
}

}  // namespace

int DefaultMaxResolution(BackendKind kind) { return kind == BackendKind::kCuda ? 1024 : 128; }

LevelChoice ChooseLevels(int levels, double pixels_across_box, int start_resolution, int max_resolution) {
  LevelChoice c;
  c.pixels_across_box = pixels_across_box;
  c.start_resolution = start_resolution;
  if (levels > 0) {
    c.levels = levels;
    return c;
  }
  c.automatic = true;
  c.max_resolution = max_resolution;
  int cap = 1;  // the most levels whose finest grid stays within max_resolution
  while (cap < kMaxLevels && (start_resolution << cap) <= max_resolution) ++cap;
  c.levels = std::min(LevelsReaching(pixels_across_box, start_resolution), cap);
  return c;
}

std::string LevelChoice::Describe() const {
  const int pixels = static_cast<int>(std::lround(pixels_across_box));
  std::string s = StrCat("levels: ", levels, " (", start_resolution, "^3", levels > 1 ? StrCat(" to ", Finest(), "^3") : "",
                         ")", automatic ? " chosen from the photos" : " as given");
  if (pixels_across_box <= 0) return s + "; no training views to measure the photos' resolution by";
  s += StrCat(", which resolve about ", pixels, " cells across the box (one pixel a cell in the median view)");
  const int best = LevelsReaching(pixels_across_box, start_resolution);
  const int best_n = start_resolution << (best - 1);
  if (automatic) {
    if (best > levels) s += StrCat("; --max-resolution ", max_resolution, " stops short of ", best_n, "^3");
  } else if (best > levels) {
    s += StrCat("; --levels ", best, " would reach ", best_n, "^3");
  } else if (best < levels) {
    s += StrCat("; finer than the photos: --levels ", best, " would do");
  }
  return s;
}

}  // namespace perf::recon
