// The last route of the ghost repair (ghost_repair.h), for photos too small for COLMAP to match
// (the example's 200 px: 0 of 5 registered again): each ghost group moved, with the points only it
// sees, by the similarity that takes its copy of the object onto the object: its in-box points'
// centre onto the main group's, scaled by the ratio of the two groups' median camera distances
// from those centres. No rotation: the copy's turn about its centre is not known without matches,
// and camera refinement and the eval's pose fit correct a part of it. A point the group shares
// with other photos keeps its place and loses the group's observations. On the example it raised
// DSCF5608's in-mask PSNR from 15.2 to 19.2 dB (docs/tuning.md "Ghost repair").
#pragma once

#include <vector>

#include "sfm_import/colmap_model.h"
#include "sfm_import/ghost_groups.h"

namespace perf {

// `given` with each of `ghosts` moved onto the object (same ids).
colmap::Reconstruction MoveGhostsOntoObject(colmap::Reconstruction given, const std::vector<GhostGroup>& ghosts);

}  // namespace perf
