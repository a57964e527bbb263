// How many hierarchy levels a run has: as given (--levels), or chosen from the photos so that the
// finest cell is about one pixel of the median training view (PixelsAcrossBox), capped by
// --max-resolution. Memory caps automatic levels further, once each level's occupied bricks are
// known (HierarchyOptions::stop_when_out_of_memory).
#pragma once

#include <string>

#include "recon_cuda/solve/backend.h"

namespace perf::recon {

// The finest grid automatic levels may reach when --max-resolution is 0. CPU: 128 (a small CPU
// fits 128^3 in minutes; 256^3 takes about three times as long, docs/tuning.md "Sparse levels");
// GPU: 1024.
int DefaultMaxResolution(BackendKind kind);

struct LevelChoice {
  int levels = 0;
  bool automatic = false;        // chosen from the photos (no --levels)
  int max_resolution = 0;        // the cap an automatic choice went by
  double pixels_across_box = 0;  // the photos' resolution in cells across the box (0: unknown)
  int start_resolution = 32;

  int Finest() const { return start_resolution << (levels - 1); }
  // One line for the terminal, e.g. "levels: 3 (32^3 to 128^3) chosen from the photos, which
  // resolve about 215 cells across the box ...; --max-resolution 128 stops short of 256^3".
  std::string Describe() const;
};

// levels > 0: as given. Else the fewest levels (1 to 6) whose finest grid has at least
// pixels_across_box cells across, and at most as many as keep the finest grid within
// max_resolution (at least one level).
LevelChoice ChooseLevels(int levels, double pixels_across_box, int start_resolution, int max_resolution);

}  // namespace perf::recon
