// The hierarchy's callbacks of `perf reconstruct` (HierarchyCallbacks): per level and iteration
// it logs, reports progress, scores the held-out views, writes previews and checkpoints; after
// the first level it checks the box's faces (box_check.h) and the photos' fits (photo_fit.h).
// Internal to run/.
#pragma once

#include <memory>
#include <vector>

#include "common/stopwatch.h"
#include "recon_cuda/run/box_check.h"
#include "recon_cuda/run/photo_corrections.h"
#include "recon_cuda/run/reconstruct_run.h"
#include "recon_cuda/run/time_plan.h"

namespace perf::recon {

class LevelMonitor {
 public:
  explicit LevelMonitor(ReconstructRun& run);

  HierarchyCallbacks Callbacks();

  // After the first level: the faces the object goes on beyond, for which that level's fit was
  // discarded (the hierarchy ends there); empty when the box holds it or may not grow.
  const std::vector<int>& faces_to_grow() const { return grow_faces_; }
  const std::vector<BoxFace>& box_faces() const { return box_faces_; }
  // The box has grown: the first level starts again.
  void BoxGrown() { grow_faces_.clear(); }

 private:
  void LevelStarted(const HierarchyLevel& h);
  bool Iteration(const HierarchyLevel& h, const IterationSummary& s);
  void LevelDone(const HierarchyLevel& h, const SolverSummary& summary, const std::vector<float>& x);
  void OutOfMemory(const HierarchyLevel& h);
  // With a time budget: whether level `level` runs (TimePlanner::BeforeLevel), and after an
  // iteration what the plan says (the stages after the solve measured at a level's first).
  bool PlanAllowsLevel(int level);
  void FollowPlan(const HierarchyLevel& h, int done);

  // The first level's box faces: the warning, and the faces to grow.
  void CheckBox(const HierarchyLevel& h, const std::vector<float>& x);
  // The photos' exposures at the level's current parameters (none when it solves none), read
  // from the backend once for a callback's scoring and preview.
  PhotoCorrections CorrectionsAt(const HierarchyLevel& h);
  // The mean PSNR over every rank's held-out views (collective).
  double HeldOutPsnr(VecId params, const PhotoCorrections& exposures);
  // The level's refined cameras: recon.json's "poses", the log, scene.json's refined poses and,
  // after the last level, the warning naming large corrections. A level that refines none drops
  // an earlier run's refined poses from scene.json.
  void ReportPoses(const HierarchyLevel& h, const PhotoCorrections& fitted);
  void WritePreview(const HierarchyLevel& h, int iteration, const PhotoCorrections& exposures);
  // ReconstructOptions::on_volume after iteration `iteration`: the level's first, then at most every
  // volume_every_seconds.
  void HandOverVolume(const HierarchyLevel& h, int iteration);
  // The log's "level" line; with several ranks, every rank's pass and sum seconds (collective).
  nlohmann::json LevelLine(const SolverSummary& summary);
  // Ends the level's clock: its solver seconds (held-out scoring and previews left out).
  double EndLevelClock();
  int64_t SummedBytes() const { return run_.ranks != nullptr ? run_.ranks->bytes_summed() : 0; }

  ReconstructRun& run_;
  const ReconstructOptions& o_;
  double elapsed_ = 0;  // solver time so far (excludes held-out evaluation and previews)
  WallClock::time_point t_level_ = WallClock::now();
  double eval_seconds_ = 0;  // held-out evaluation and previews within the level
  double preview_seconds_ = 0;  // the previews alone within the level (what --view adds)
  double volume_seconds_ = 0;   // the volumes handed to a live page within the level (HandOverVolume)
  WallClock::time_point volume_at_{};  // when the last was
  LevelReport lr_;
  double level_start_elapsed_ = 0, iter_time_ = 0;  // for the log's elapsed solver time
  int held_out_iteration_ = -1;  // the iteration whose held-out PSNR was logged last
  double held_out_psnr_ = 0;
  int64_t summed_at_level_ = 0, summed_at_iteration_ = 0;  // bytes summed across ranks so far
  double pass_at_level_ = 0, sum_at_level_ = 0;            // this rank's pass and sum seconds so far
  std::vector<BoxFace> box_faces_;
  std::vector<int> grow_faces_;
  std::unique_ptr<TimePlanner> plan_;  // with ReconstructOptions::time_budget, in one process
  PlanVerdict verdict_ = PlanVerdict::kGoOn;
};

}  // namespace perf::recon
