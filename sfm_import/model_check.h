// What a COLMAP model gets right and wrong, as perf import would see it: the photos it registers,
// its points' mean reprojection error, the poses that look wrong (bad_poses.h) and the ghost
// groups (ghost_groups.h) inside the box import would place. Compares the user's model with one
// made again from the photos (ghost_repair.h).
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "sfm_import/colmap_model.h"
#include "sfm_import/ghost_groups.h"

namespace perf {

struct ModelCheck {
  int registered = 0;         // images in the model
  int points = 0;             // its 3-D points
  double mean_error = 0;      // mean reprojection error of its points (px; 0: not recorded)
  std::map<std::string, std::string> bad_poses;  // name -> why (FindBadPoses)
  std::vector<GhostGroup> ghosts;
  int ghost_photos = 0;       // photos in the ghost groups
  // The fraction of the well-placed cameras that look at the point closest to all their optical
  // axes (bounds.h CamerasLookingAt; 0: no such point): an object capture's cameras all do.
  double looked_at = 0;
  struct Focal {
    uint64_t width = 0, height = 0;
    double fx = 0, fy = 0;
  };
  std::vector<Focal> focals;  // each camera's

  // e.g. "84 photos, 52114 points at 0.47 px, no pose looks wrong, no ghost group".
  std::string Describe() const;
};

// The check of `rec`: its box placed as perf import places it (EstimateBounds over the cameras
// whose pose does not look wrong, the COLMAP intrinsics' focal lengths and centre).
ModelCheck CheckModel(const colmap::Reconstruction& rec);

// Whether `repaired` is better than `user` for the reconstruction: no ghost group, at least as many
// photos whose pose looks right as the user's model less 5 % (at least one), a mean reprojection
// error within 1.5 times the user's (or 0.5 px above it), square pixels (each camera's fx and fy
// within 1 % of each other, or no further apart than the user's: bonsai's OPENCV remakes at 4-6 %
// apart were wrong; its focal length may differ, bonsai's right remakes at 819-827 px against the
// shipped model's 731 / 722), and, where the user's cameras look at a common point, as many of its
// own doing so (less 10 %). `why` says which held or failed.
bool RepairIsBetter(const ModelCheck& repaired, const ModelCheck& user, std::string* why);

// Why `check` looks wrong for an object capture ("it holds 2 ghost groups (16 photos)", "only 41 %
// of its cameras look at a common point (at least 80 % expected)", a camera whose fx and fy differ
// by more than 1 %), or "": perf sfm's models are made again from every pair where this says
// something (colmap_runner.h check_model). Bonsai's right models: 100 %, fx = fy; wrong ones of
// its photos: 41 % and 73 %, or 100 % on an orbit bent in its first half with fx / fy 2 % apart.
std::string ObjectModelDoubt(const ModelCheck& check);
// ObjectModelDoubt of the model in `dir` ("" where it cannot be read: the import names that).
std::string ObjectModelDoubtOf(const std::filesystem::path& dir);

}  // namespace perf
