// Groups of photos that COLMAP placed consistently among themselves but not with the rest: the
// sparse points inside the box that such a group sees are seen by none of the other photos, and
// their centre lies far from where the others see the object. COLMAP has reconstructed the object
// twice (a ghost), so the group's poses disagree with the others'; camera refinement, which moves
// each photo a little, repairs only part of it (docs/tuning.md).
//
// shared/data/bonsai has two, the start of the capture: DSCF5605 to 5635 (11 photos) see 624
// in-box points 2.6 units (2.9 times the object's RMS radius) from the 3577 that the 60 photos from
// DSCF5668 on see, and DSCF5638 to 5659 (5 photos) 115 points 2.3 units away. Rendered from the
// volume, the bonsai lands left of where their photos show it. The example (examples/bonsai_mini)
// has 5 of the first group. Leaving those out of training lowered its held-out PSNR (19.24 against
// 19.82 dB: nothing else sees that side), so perf import names such groups in a warning and keeps
// them. A new model of the same photos (perf sfm) had no ghost, and the early held-out views scored
// 3-4 dB more (docs/tuning.md "A ghost object in COLMAP's model").
#pragma once

#include <array>
#include <map>
#include <string>
#include <vector>

#include "sfm_import/colmap_model.h"
#include "workspace/scene.h"

namespace perf {

struct GhostGroupOptions {
  // Two photos are linked when they see at least this many of the same in-box points; a group is
  // a connected set of linked photos.
  int min_shared_points = 1;
  // A group with fewer photos or in-box points than these is not named: a few stray photos.
  int min_photos = 3;
  int min_points = 20;
  // ... nor one whose object centre is within this many times the main group's RMS radius of the
  // main group's centre: the far side of one object, seen by photos that share no point with the
  // front, has its centre within about one radius. Bonsai's two ghost groups: 2.9 and 2.5;
  // the two sides of a model of the same photos without a ghost (perf sfm): 0.8.
  double min_separation = 2.0;
};

struct GhostGroup {
  std::vector<std::string> names;  // the group's photos, sorted
  int points = 0;                  // in-box sparse points the group sees
  double separation = 0;           // from the group's in-box centre to the main group's (world units)
  double main_radius = 0;          // RMS distance of the main group's in-box points from their centre
  int main_photos = 0, main_points = 0;
  std::array<double, 3> centre{}, main_centre{};  // the group's in-box points' mean, the main group's
  // e.g. "11 photos (DSCF5605.JPG ... DSCF5635.JPG) see 624 sparse points inside the box 2.6 units
  // (2.9 times the object's radius) from the 3577 that the other 60 photos see, and share none".
  std::string Describe() const;
  // Describe(), what it means and what to do, and every photo's name: perf import's warning.
  std::string Warning() const;
  // What scene.json's "pose_doubt" of each of the group's photos says: Describe() and its meaning.
  std::string Doubt() const;
};

// The groups of `rec` that see a second copy of the object in `box`, largest first. Photos named
// in `left_out` (name -> why: the wrong poses, bad_poses.h) take no part. The main group is the
// one with the most photos; nothing is found when only one group sees in-box points.
std::vector<GhostGroup> FindGhostGroups(const colmap::Reconstruction& rec, const SceneBox& box,
                                        const std::map<std::string, std::string>& left_out,
                                        const GhostGroupOptions& options = {});

// FindGhostGroups in `scene`'s box; each group's photos get its Doubt() as their pose_doubt in
// `scene`, and each group a warning (Warning()), returned for perf import to print.
std::vector<std::string> MarkGhostGroups(const colmap::Reconstruction& rec,
                                         const std::map<std::string, std::string>& left_out, Scene* scene);

// Marks the photos of each of `groups` (moved onto the object, ghost_move.h: RepairResult::TurnUnknown) in
// `scene`: turn_group k for the k-th group, and a pose_doubt saying what was done and what
// perf reconstruct does next. Names not in the scene are passed over.
void MarkTurnUnknown(const std::vector<std::vector<std::string>>& groups, Scene* scene);

}  // namespace perf
