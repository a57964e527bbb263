// The first route of the ghost repair (ghost_repair.h): the ghost group's photos registered
// again into the user's model without them. COLMAP extracts features with the model's own
// cameras (fixed), matches each photo with the photos it shares most points with in the model and
// the group's with every other photo (or, for large groups, their neighbours in capture order),
// triangulates points for the model less the group with its poses as given, and registers the
// group into it. Every other photo keeps its pose as given, to the bit; the group gets new poses
// and the points are new. Work files go to WORKSPACE/repair/register/ (COLMAP's log there).
// On bonsai with eight photos moved by a similarity it put them back within 0.06 degrees and
// 1.4 % of their distance from the origin in about 4 minutes on 2 cores (docs/tuning.md).
#pragma once

#include <filesystem>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include "sfm_import/colmap_model.h"

namespace perf {

struct RegisterGroupOptions {
  std::filesystem::path images;  // the photos' folder
  std::filesystem::path dir;     // work folder (WORKSPACE/repair/register)
  int threads = -1;              // COLMAP's (-1: all cores)
  // The group is matched with every other photo while that is at most this many pairs; beyond,
  // with the photos within `order_neighbours` of each of its own in capture (name) order.
  int all_pairs_limit = 1000;
  int order_neighbours = 15;
  int covisible_neighbours = 5;  // each other photo matched with this many it shares most points with
  std::function<void(const std::string&)> say;  // progress lines
  std::function<void()> check_stop;             // throws to stop (Ctrl-C) while COLMAP runs
};

struct GroupRegistration {
  // The user's model with the group placed again: the same image and camera ids, the other
  // photos' poses as given, new points; a group photo COLMAP could not register is left out.
  colmap::Reconstruction model;
  std::vector<std::string> placed, left_out;  // the group's photos
};

// `camera`'s parameters as COLMAP's --ImageReader.camera_params takes them ("731.4,722.35,...").
std::string CameraParamsArgument(const colmap::Camera& camera);

// Throws IoError when a COLMAP step fails (with its log's tail), InputError when a photo of the
// group is missing from `options.images`, and Interrupted.
GroupRegistration RegisterGroupAgain(const colmap::Reconstruction& given, const std::set<std::string>& group,
                                     const RegisterGroupOptions& options);

}  // namespace perf
