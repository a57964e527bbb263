// Photos that COLMAP registered in the wrong place (issue 16). Such a pose sits far outside the
// cameras' spread and sees fewer of the model's points than most: shared/data/bonsai has three,
// 17.7-19.2 units from the cameras' median centre where the median camera is 3.8 away, seeing
// 259-937 points where the median photo sees 1067. Training on one fits noise; scoring on one scores noise.
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
};

struct BadPose {
  std::string name;                    // the COLMAP image name
  double distance = 0, median_distance = 0;  // from the cameras' median centre
  int points = 0, median_points = 0;   // sparse points seen (point2D with a 3-D point)
  std::string Describe() const;        // e.g. "DSCF5842.JPG: 18.2 units from the cameras' centre (median 3.7), 259 points (median 1064)"
};

// The images of `rec` that are both far and weak, in image-id order. Fewer than 4 images: none.
std::vector<BadPose> FindBadPoses(const colmap::Reconstruction& rec, const BadPoseOptions& options = {});

}  // namespace perf
