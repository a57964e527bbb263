// Photos that COLMAP registered in the wrong place. Such a pose sits far outside the
// cameras' spread and either sees fewer of the model's points than most, or, in a capture whose
// cameras look at a common point, does not have that point in its view although its photo shows
// the object like its neighbours. shared/data/bonsai has five: DSCF5842, 5845 and 5848 17.7-19.2
// units from the cameras' median centre where the median camera is 3.8 away, seeing 259-937 points
// where the median photo sees 1067; DSCF5644 and 5647 1.8 times as far from the object as the
// median camera, turned 76-80 degrees away from it, seeing 3011-3265 points (the most of any
// photo). Training on one fits noise; scoring on one scores noise.
//
// perf import marks them "excluded" in scene.json (out of training and scoring; --keep-bad-poses
// keeps them). A photometric test after the first level would not find them: the learned shells
// fit a wrong pose about as well as the others (docs/tuning.md).
#pragma once

#include <string>
#include <vector>

#include "sfm_import/colmap_model.h"

namespace perf {

struct BadPoseOptions {
  // A pose is far when its camera centre is more than this many times the median camera's
  // distance from the cameras' median centre (component-wise median: robust to the outliers).
  // On bonsai the good poses reach 1.7x, the wrong ones 4.7-5.1x.
  double max_distance_ratio = 3.0;
  // ... and weak when it sees fewer than this fraction of the median photo's sparse points. The
  // count alone does not tell (good bonsai photos see 108-3265 points, the wrong ones 259-937):
  // it only keeps a far photo that sees more than most, a wide shot, from being flagged.
  double max_point_fraction = 1.0;
  // A pose is also wrong when the point the cameras look at (bounds.h ClosestPointToAxes, over
  // the inward-looking cameras) is out of its view and it is more than this many times the median
  // camera's distance from that point. Only where most cameras look at a common point (a 360-degree
  // capture). On bonsai the good poses are within 1.16x and all see that point (at most 13 degrees
  // off their axis); DSCF5644/5647 are at 1.8x and 76-80 degrees off, the other three at 4-4.4x.
  double away_distance_ratio = 1.5;
};

struct BadPose {
  std::string name;                    // the COLMAP image name
  double distance = 0, median_distance = 0;  // from the cameras' median centre
  int points = 0, median_points = 0;   // sparse points seen (point2D with a 3-D point)
  // Degrees between the optical axis and the point the cameras look at, when that point is out
  // of the photo's view (the second rule); < 0 otherwise.
  double away_degrees = -1;
  double from_looked_at = 0, median_from_looked_at = 0;  // distances from that point (second rule)
  // e.g. "DSCF5842.JPG: 18.2 units from the cameras' centre (median 3.7), 259 points (median
  // 1064)", and for the second rule ", 8.0 units (median 4.5) from the point the cameras look at,
  // which is 80 degrees off its axis and out of its view".
  std::string Describe() const;
  std::string Why() const;  // Describe() without the name
};

// The images of `rec` that are far and weak, or far and looking away, in image-id order. Fewer than 4 images: none.
std::vector<BadPose> FindBadPoses(const colmap::Reconstruction& rec, const BadPoseOptions& options = {});

}  // namespace perf
