// A model made again from the photos (the ghost repair's perf sfm route, ghost_repair.h) put in
// the user's model's frame: the similarity (Eigen::umeyama on the camera centres) that best takes
// its photos onto the same photos of the user's model, left out those the caller doubts (a ghost
// group, a pose that looks wrong). Users keep their COLMAP frame for the assets (perf export), as
// they would with the model they gave.
#pragma once

#include <set>
#include <string>

#include "sfm_import/colmap_model.h"

namespace perf {

struct ModelAlignment {
  int photos = 0;           // photos the similarity was fitted on (0: too few, `rec` as it was)
  double scale = 1;         // the similarity's scale
  double median_error = 0;  // median distance of a fitted photo's centre from the user's, after
  double camera_radius = 0; // median distance of the user's fitted centres from their mean
};

// Moves `rec` (poses and points) onto `reference` by the similarity fitted on the photos both hold,
// `exclude` left out; needs at least 3 such photos, else leaves `rec` as it is (photos = 0).
ModelAlignment AlignModelOnto(colmap::Reconstruction& rec, const colmap::Reconstruction& reference,
                              const std::set<std::string>& exclude);

}  // namespace perf
