// The last route of the ghost repair (ghost_repair.h), for photos too small for COLMAP to match
// (the example's 200 px: 0 of 5 registered again): each ghost group moved, with the points only it
// sees, by the similarity that takes its copy of the object onto the object: its in-box points'
// centre onto the main group's, scaled by the ratio of the two groups' median camera distances
// from those centres. No rotation: the copy's turn about its centre is not known without matches,
// and camera refinement and the eval's pose fit correct a part of it. A point the group shares
// with other photos keeps its place and loses the group's observations. On the example it raised
// DSCF5608's in-mask PSNR from 15.2 to 19.2 dB (docs/tuning.md "Ghost repair").
#pragma once

#include <map>
#include <string>
#include <vector>

#include "sfm_import/colmap_model.h"
#include "sfm_import/ghost_groups.h"

namespace perf {

// `given` with each of `ghosts` moved onto the object (same ids).
colmap::Reconstruction MoveGhostsOntoObject(colmap::Reconstruction given, const std::vector<GhostGroup>& ghosts);

// `registered` (the user's model with the groups registered again, in its ids: ghost_register.h)
// with each photo of `ghosts` that it left out, or placed where its pose looks wrong (`wrong`,
// name -> why: bad_poses.h), put back where MoveGhostsOntoObject puts it, seeing no points. The
// names of those photos go to `moved`. On bonsai COLMAP registered 2 of its 16 ghost photos 14 and
// 25 units from the others (docs/tuning.md).
colmap::Reconstruction MoveWhatWasNotPlaced(colmap::Reconstruction registered, const colmap::Reconstruction& given,
                                            const std::vector<GhostGroup>& ghosts,
                                            const std::map<std::string, std::string>& wrong,
                                            std::vector<std::string>* moved);

}  // namespace perf
