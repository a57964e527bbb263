// COLMAP's mistakes repaired, not only named: where a user's model (perf import / perf run
// --colmap) holds a ghost group (ghost_groups.h) and its photos are at hand, three routes are tried
// in turn, each checked against the user's model (model_check.h): the model made again from the
// photos (perf sfm into WORKSPACE/repair/, one focal length, put in the user's frame:
// model_align.h), the group registered again into the model without it (ghost_register.h), and
// each group moved onto the object (ghost_move.h, for photos too small to match). On bonsai's
// shipped model the model made again scored above the group registered again into it, whose other
// cameras and focal length COLMAP's OPENCV fit had bent (docs/tuning.md "Ghost repair"). The first
// that is better goes to WORKSPACE/sparse_repaired/ and is imported instead, saying why either way;
// the user's model is only read. WORKSPACE/repair/repair.json records the tries and the decision
// for that model (its path and time), so that a run again does not repeat them.
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "sfm_import/model_check.h"

namespace perf {

struct RepairOptions {
  std::filesystem::path model;      // the user's COLMAP model folder
  std::filesystem::path images;     // its photos (empty: <model>/../../images, as perf import)
  std::filesystem::path workspace;
  bool repair = true;               // false (--no-repair): the model as given
  int threads = 0;                  // COLMAP's (0: all cores)
  // The routes tried, in this order, until one is better: "sfm", "register", "move" (all three).
  std::set<std::string> routes = {"sfm", "register", "move"};
  std::function<void(const std::string&)> say;  // lines for the terminal
  std::function<void()> check_stop;             // throws to stop (Ctrl-C) while COLMAP runs
  // Seconds left of perf run's time budget (unset: none): the model made again matches as perf
  // sfm does under one (SfmOptions::seconds_left).
  std::function<double()> seconds_left;
};

struct RepairResult {
  std::filesystem::path model;   // what to import: options.model or WORKSPACE/sparse_repaired
  std::filesystem::path images;  // the photos' folder, resolved
  bool attempted = false;        // a ghost was found and a new model made (or recorded before)
  bool used = false;             // the new model is imported
  std::string why;               // the decision in words
  // "register" (the group registered again: ghost_register.h), "sfm" (made again) or "move"
  // (moved onto the object: ghost_move.h)
  std::string route;
  std::vector<std::string> tries;  // what each route made of it, in order
  ModelCheck before, after;
  double seconds = 0;
  nlohmann::json ToJson() const;
  // The groups moved onto the object (route "move", used), each its photos: their turn about the
  // object is not known, and the import marks them for perf reconstruct to search
  // (ImportOptions::turn_unknown).
  std::vector<std::vector<std::string>> TurnUnknown() const;
};

// Throws what reading the user's model throws, and Interrupted; a failed perf sfm is a decision
// (the model kept), not an error.
RepairResult RepairModel(const RepairOptions& options);

}  // namespace perf
