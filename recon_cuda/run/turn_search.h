// The place of a group of photos that the ghost repair moved onto the object without matches
// (sfm_import/ghost_move.h; scene.json "turn_group"): the move puts the group's copy of the
// object on the object, but not its turn about it, nor exactly its size. Before the hierarchy,
// perf reconstruct fits the first level from the other training photos, then (1) turns each group
// about the box centre (coarse: all round the cameras' up axis; then about three axes, the step
// halved each time), each turn scored by the group's training photos rendered against that
// volume; (2) fits each of those photos' cameras alone from the best turn (pose_fit.h); (3) takes
// the similarity that carries the group's imported cameras onto the fitted ones (GroupMove::
// Between). The better of the turn and the similarity is used where the group's photos fit better
// by min_gain_db; the group's held-out photos move with it (found without them). scene.json gets
// the moved poses and the group's mark is cleared, so a run again does not search again;
// recon.json's "turn_search" records each search.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "recon_cuda/data/training_data.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

struct ReconstructRun;

struct TurnSearchOptions {
  int max_pixels = 64;        // the photos are scored downscaled to at most this many pixels across
  double step_degrees = 10;   // the coarse turns about the up axis, all round
  int refinements = 3;        // then each a 3 x 3 x 3 neighbourhood about three axes, the step halved
  double min_gain_db = 1.0;   // a move is used only where the group's photos fit this much better
  int fit_pixels = 100;       // the pose fit's photos at most this many pixels across (as perf eval's)
};

// A similarity of the world: a pose [R | c] becomes [rotation R | scale rotation c + shift].
struct GroupMove {
  double scale = 1;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();

  Eigen::Matrix<double, 3, 4> Apply(const Eigen::Matrix<double, 3, 4>& world_from_cam) const;
  double Degrees() const;  // of the rotation
  // `turn` about `pivot`.
  static GroupMove Turn(const Eigen::Vector3d& pivot, const Eigen::Matrix3d& turn);
  // The move that best carries the cameras `from` onto `to` (same order, at least one): the
  // rotation their rotations' mean (R_to R_from^T), then the scale and shift of the centres by
  // least squares (scale 1 for one camera).
  static GroupMove Between(const std::vector<Eigen::Matrix<double, 3, 4>>& from,
                           const std::vector<Eigen::Matrix<double, 3, 4>>& to);
};

struct TurnSearch {
  int group = 0;
  std::vector<std::string> photos;  // every photo of the group, any split
  int scored = 0;                   // its training photos, which score each turn
  int turns_tried = 0;
  GroupMove move;          // the one chosen (the identity when none is used)
  std::string chosen;      // "turn" or "similarity"
  double turn_degrees = 0;  // of the best turn
  // The scored photos' mean PSNR: as imported, turned, each camera fitted alone, and moved by the
  // similarity.
  double psnr_before = 0, psnr_turned = 0, psnr_fitted = 0, psnr_moved = 0;
  bool used = false;
  std::string why;  // the decision in words
  double turn_seconds = 0, fit_seconds = 0;  // the turns scored; the pose fits and the similarity
  nlohmann::json ToJson() const;
};

// The best turn found for a score (higher is better) of a turn: the coarse turns about `up`,
// then `refinements` rounds of the 27 turns about up, the axis across the group's direction
// `toward` (from the pivot, made perpendicular to up) and that direction, the step halved each
// round. `tried` counts the turns scored.
Eigen::Matrix3d FindTurn(const std::function<double(const Eigen::Matrix3d&)>& score, const Eigen::Vector3d& up,
                         const Eigen::Vector3d& toward, const TurnSearchOptions& options, int* tried = nullptr);

// Searches every marked group of run.scene (above), writes scene.json and moves the loaded
// photos' cameras where a turn is used. Before a fresh hierarchy; a single process only (with
// several ranks it says so and leaves the marks).
std::vector<TurnSearch> SearchTurns(ReconstructRun& run, const TurnSearchOptions& options);

}  // namespace perf::recon
