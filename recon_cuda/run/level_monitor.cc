#include "recon_cuda/run/level_monitor.h"

#include <algorithm>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/system_memory.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/evaluation.h"
#include "recon_cuda/run/photo_fit.h"
#include "recon_cuda/run/refined_poses.h"
#include "workspace/image_io.h"

namespace perf::recon {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

Checkpoint MakeCheckpoint(const Scene& scene, int level, const VolumeShape& shape, int iterations, SolverType type,
                          std::vector<float> params) {
  Checkpoint c;
  c.level = level;
  c.shape = shape;
  c.iterations = iterations;
  c.solver = type == SolverType::kAdam ? 1 : 0;
  c.placement = VolumePlacement::FromScene(scene);
  c.params = std::move(params);
  return c;
}

}  // namespace

LevelMonitor::LevelMonitor(ReconstructRun& run) : run_(run), o_(run.options) {
  if (!o_.time_budget) return;
  if (run_.comm.size() > 1) {
    run_.Say("the time budget is not applied under mpirun: every level runs its iterations");
    return;
  }
  // Each level's iteration cap and rays (its pyramid downscale of the training photos).
  const HierarchyOptions& ho = run_.hierarchy;
  std::vector<int> caps;
  std::vector<int64_t> rays;
  for (int level = 0; level < run_.levels; ++level) {
    caps.push_back(ho.IterationsAt(level));
    const int factor = LevelDownscale(ho, run_.train_views, run_.geometry, ho.start_resolution << level, level);
    int64_t n = 0;
    for (const ViewFrustum& v : run_.train_views) n += static_cast<int64_t>(v.width / factor) * (v.height / factor);
    rays.push_back(n);
  }
  plan_ = std::make_unique<TimePlanner>(*o_.time_budget, ho.start_resolution, std::move(caps), std::move(rays));
}

HierarchyCallbacks LevelMonitor::Callbacks() {
  HierarchyCallbacks cb;
  cb.level_started = [this](const HierarchyLevel& h) { LevelStarted(h); };
  cb.iteration = [this](const HierarchyLevel& h, const IterationSummary& s) { return Iteration(h, s); };
  cb.level_done = [this](const HierarchyLevel& h, const SolverSummary& summary, const std::vector<float>& x) {
    LevelDone(h, summary, x);
  };
  cb.before_level = [this](int level) { return grow_faces_.empty() && PlanAllowsLevel(level); };
  cb.end_level = [this](const HierarchyLevel&, const IterationSummary&) { return verdict_ == PlanVerdict::kEndLevel; };
  cb.out_of_memory = [this](const HierarchyLevel& h) { OutOfMemory(h); };
  return cb;
}

void LevelMonitor::LevelStarted(const HierarchyLevel& h) {
  Communicator& comm = run_.comm;
  if (plan_) plan_->LevelStarted(h.level);
  lr_ = LevelReport{};
  lr_.level = h.level;
  lr_.shape = h.shape;
  lr_.image_downscale = h.image_downscale;
  lr_.rays = comm.size() > 1 ? comm.ShareOf(h.rays).total : h.rays;  // every rank's
  held_out_iteration_ = -1;
  level_start_elapsed_ = elapsed_ + SecondsSince(t_level_);  // setup (rays, SetLevel) counts
  iter_time_ = 0;
  summed_at_level_ = summed_at_iteration_ = SummedBytes();
  if (run_.ranks != nullptr) {
    pass_at_level_ = run_.ranks->pass_seconds();
    sum_at_level_ = run_.ranks->sum_seconds();
  }
  const MemoryEstimate& mem = h.memory;
  run_.Say(StrCat("level ", h.level + 1, "/", run_.levels, ": ", DescribeShape(h.shape), ", ", lr_.rays, " rays",
                  lr_.image_downscale > 1 ? StrCat(" (images / ", lr_.image_downscale, ")") : std::string(),
                  comm.size() > 1 ? "; memory per rank: vectors " : "; memory: vectors ", FormatByteCount(mem.vectors),
                  ", per-thread sums ", FormatByteCount(mem.scratch), ", Jacobian cache ",
                  !run_.backend->CachesJacobian() ? std::string("off (recomputing)")
                  : mem.jacobian_wanted > 0
                      ? StrCat(FormatByteCount(mem.jacobian_cache), " of ", FormatByteCount(mem.jacobian_wanted),
                               " wanted (the rays beyond it are recomputed)")
                      : FormatByteCount(mem.jacobian_cache),
                  mem.available > 0 ? StrCat(" of ", FormatByteCount(mem.available), " available") : std::string()));
}

bool LevelMonitor::Iteration(const HierarchyLevel& h, const IterationSummary& s) {
  iter_time_ += s.seconds_total;
  json line{{"event", "iteration"}, {"level", lr_.level}, {"n", lr_.shape.n}, {"solver", SolverName(h.solver.type)}};
  line.update(s.ToJson());
  line["rays"] = lr_.rays;
  line["elapsed"] = level_start_elapsed_ + iter_time_;
  if (run_.ranks != nullptr) {
    line["ranks"] = run_.comm.size();
    line["summed_bytes"] = SummedBytes() - summed_at_iteration_;
    summed_at_iteration_ = SummedBytes();
  }
  const bool last_it = s.iteration + 1 == h.solver.max_iterations;
  const bool score = run_.test_views > 0 && o_.eval_every > 0 && ((s.iteration + 1) % o_.eval_every == 0 || last_it);
  const bool preview = run_.root && o_.preview_every > 0 && ((s.iteration + 1) % o_.preview_every == 0 || last_it);
  const PhotoCorrections exposures = score || preview ? CorrectionsAt(h) : PhotoCorrections();
  if (score) {
    held_out_psnr_ = HeldOutPsnr(h.params, exposures);
    held_out_iteration_ = s.iteration;
    line["test_psnr"] = held_out_psnr_;
  }
  if (preview) WritePreview(h, s.iteration, exposures);
  HandOverVolume(h, s.iteration);
  run_.log.Write(line);
  ReconstructOptions::Event e;
  e.level = h.level;
  e.levels = run_.levels;
  e.iteration = s.iteration + 1;
  e.iterations = h.solver.max_iterations;
  e.cost = s.cost_after;
  e.train_psnr = s.train_psnr;
  run_.Emit(e);
  FollowPlan(h, s.iteration + 1);
  return verdict_ != PlanVerdict::kStop;
}

bool LevelMonitor::PlanAllowsLevel(int level) {
  if (!plan_) return true;
  const bool runs = plan_->BeforeLevel(level);
  if (const std::string m = plan_->TakeMessage(); !m.empty()) run_.Say(m);
  run_.result.time_plan = plan_->ToJson();
  return runs;
}

void LevelMonitor::FollowPlan(const HierarchyLevel& h, int done) {
  verdict_ = PlanVerdict::kGoOn;
  if (!plan_) return;
  const auto measure = [&] {
    if (!o_.time_budget->after_solve) return 0.0;
    const auto t0 = WallClock::now();
    const double seconds = o_.time_budget->after_solve(run_.backend.get(), h.params, run_.scene);
    eval_seconds_ += SecondsSince(t0);
    return seconds;
  };
  verdict_ = plan_->AfterIteration(h.level, done, measure);
  if (const std::string m = plan_->TakeMessage(); !m.empty()) run_.Say(m);
  run_.result.time_plan = plan_->ToJson();
}

void LevelMonitor::LevelDone(const HierarchyLevel& h, const SolverSummary& solved, const std::vector<float>& x) {
  ReconstructResult& result = run_.result;
  SolverSummary summary = solved;  // a level the time plan ended the run in says so
  if (verdict_ == PlanVerdict::kStop && summary.status == SolverStatus::kUserAbort) summary.status = SolverStatus::kPlanned;
  if (run_.ranks != nullptr) run_.ranks->CheckInStep(h.params);
  if (h.level == 0) CheckBox(h, x);
  if (!grow_faces_.empty()) {  // this fit is discarded (before_level ends the hierarchy here)
    result.solve_seconds += EndLevelClock();
    preview_seconds_ = volume_seconds_ = 0;
    return;
  }
  lr_.iterations = summary.iterations;
  lr_.cost = summary.final_cost;
  lr_.train_psnr = summary.per_iteration.empty() ? 0 : summary.per_iteration.back().train_psnr;
  lr_.status = StatusName(summary.status);
  // None when the level solves neither exposures nor poses.
  const PhotoCorrections fitted(h.shape, x, run_.train_views, run_.geometry);
  if (h.level == 0) {
    const auto t0 = WallClock::now();
    const PhotoFits fits =
        CheckPhotoFits(run_.backend.get(), h.params, run_.train, run_.train_names, fitted, run_.comm, o_.photo_fit);
    eval_seconds_ += SecondsSince(t0);
    result.photo_fits = fits.ToJson(o_.photo_fit);
    run_.log.Write({{"event", "photo_fits"}, {"photo_fits", result.photo_fits}});
    if (!fits.poor.empty()) run_.Say("warning: " + fits.Warning(o_.photo_fit));
  }
  if (run_.test_views > 0) {
    // The last iteration's, when the log has it; else now (the backend still holds x).
    lr_.test_psnr = held_out_iteration_ == summary.iterations - 1 ? held_out_psnr_ : HeldOutPsnr(h.params, fitted);
  }
  if (!fitted.transforms().empty()) {
    result.gain_range[0] = 2, result.gain_range[1] = 0;
    for (const ColourTransform<float>& xf : fitted.transforms()) {
      for (float g : xf.gain) {
        result.gain_range[0] = std::min(result.gain_range[0], g);
        result.gain_range[1] = std::max(result.gain_range[1], g);
      }
    }
  }
  ReportPoses(h, fitted);
  if (run_.root) {
    WriteCheckpoint(CheckpointPath(o_.workspace, h.level),
                    MakeCheckpoint(run_.scene, h.level, h.shape, summary.iterations, o_.solver.type, x));
  }
  if (run_.previous) run_.previous->Discard();
  lr_.seconds = EndLevelClock();
  run_.log.Write(LevelLine(summary));
  preview_seconds_ = volume_seconds_ = 0;
  run_.Say(StrCat("level ", h.level + 1, "/", run_.levels, " done in ", lr_.seconds, " s: ", summary.BriefReport(),
                  run_.test_views == 0 ? std::string() : StrCat("; held-out PSNR ", lr_.test_psnr, " dB")));
  result.levels.push_back(lr_);
  result.solve_seconds += lr_.seconds;
  result.final_checkpoint = CheckpointPath(o_.workspace, h.level);
  result.test_psnr = lr_.test_psnr;
}

void LevelMonitor::ReportPoses(const HierarchyLevel& h, const PhotoCorrections& fitted) {
  ReconstructResult& result = run_.result;
  if (h.shape.poses == 0) {  // an earlier run's refined poses no longer describe the checkpoints
    bool stale = false;
    for (SceneImage& im : run_.scene.images) {
      stale = stale || im.refined_world_from_cam.has_value() || im.refined_focal_scale.has_value();
      im.refined_world_from_cam.reset();
      im.refined_focal_scale.reset();
    }
    if (stale && run_.root) WriteScene(run_.scene_path, run_.scene);
    return;
  }
  const Scene refined = WithRefinedPoses(run_.scene, fitted);
  const std::vector<PoseCorrection> moved = DescribeCorrections(refined);
  result.pose_corrections = CorrectionsToJson(moved);
  result.pose_warning = LargeCorrectionsWarning(moved);
  json summary = result.pose_corrections;
  summary.erase("photos");
  run_.log.Write({{"event", "poses"}, {"level", h.level}, {"poses", summary}});
  if (h.level + 1 == run_.levels && !result.pose_warning.empty()) run_.Say("warning: " + result.pose_warning);
  // Before the level's checkpoint, which stays the newer file (perf run's freshness test).
  if (run_.root) WriteScene(run_.scene_path, refined);
}

void LevelMonitor::OutOfMemory(const HierarchyLevel& h) {
  ReconstructResult& result = run_.result;
  result.memory_stop = StrCat("level ", h.level + 1, " (", DescribeShape(h.shape), ") would need ",
                              FormatByteCount(h.memory.Needed()), " but ", FormatByteCount(h.memory.available),
                              " are available");
  run_.Say(StrCat(result.memory_stop, ": the reconstruction ends at level ", h.level, " (--levels ", h.level,
                  " next time, or a smaller --max-size)"));
  if (result.final_checkpoint.empty()) {  // a resumed run whose first level did not fit
    result.final_checkpoint = CheckpointPath(o_.workspace, h.level - 1);
    result.already_complete = true;
  }
}

void LevelMonitor::CheckBox(const HierarchyLevel& h, const std::vector<float>& x) {
  ReconstructResult& result = run_.result;
  box_faces_ = BoxFaces(h.shape, run_.geometry, x);
  result.box_faces = json::array();  // the last fit's (level 0 is fitted again after a growth)
  for (const BoxFace& f : box_faces_) result.box_faces.push_back({{"face", f.name}, {"opaque_fraction", f.opaque_fraction}});
  result.box_warning = CutOffWarning(box_faces_);
  if (o_.grow_box && result.box_growths.size() < static_cast<size_t>(kMaxBoxGrowths) &&
      !FogCanLookOpaque(o_.init.box_opacity, run_.geometry, h.shape.n)) {
    grow_faces_ = FacesToGrow(box_faces_);
  }
  if (!result.box_warning.empty() && grow_faces_.empty()) run_.Say("warning: " + result.box_warning);
}

PhotoCorrections LevelMonitor::CorrectionsAt(const HierarchyLevel& h) {
  if (h.shape.exposures == 0 && h.shape.poses == 0) return PhotoCorrections();
  const auto t0 = WallClock::now();
  std::vector<float> x(static_cast<size_t>(h.shape.ParamCount()));
  run_.backend->Download(h.params, x);
  eval_seconds_ += SecondsSince(t0);
  return PhotoCorrections(h.shape, x, run_.train_views, run_.geometry);
}

double LevelMonitor::HeldOutPsnr(VecId params, const PhotoCorrections& exposures) {
  const auto t0 = WallClock::now();
  double sum[2] = {0, 0};  // PSNR, views
  for (const ViewScore& s : ScoreViews(run_.backend.get(), params, run_.test, o_.min_box_opacity, exposures)) {
    sum[0] += s.psnr;
    sum[1] += 1;
  }
  run_.comm.SumInPlace(sum);
  eval_seconds_ += SecondsSince(t0);
  return sum[1] > 0 ? sum[0] / sum[1] : 0.0;
}

void LevelMonitor::WritePreview(const HierarchyLevel& h, int iteration, const PhotoCorrections& exposures) {
  const auto t0 = WallClock::now();
  // Rank 0's (its share starts with each split's first image; ReconstructRun::preview).
  const RenderOutput r = RenderAsShot(run_.backend.get(), h.params, *run_.preview, o_.min_box_opacity, exposures);
  const fs::path p = o_.workspace / "preview" / StrCat("recon_l", h.level, "_i", iteration + 1, ".png");
  EnsureWritableDirectory(p.parent_path());
  WriteImage(p, ToImage(r), PixelFormat::kUInt8);
  eval_seconds_ += SecondsSince(t0);
  preview_seconds_ += SecondsSince(t0);
}

void LevelMonitor::HandOverVolume(const HierarchyLevel& h, int iteration) {
  if (!run_.root || !o_.on_volume) return;
  const auto t0 = WallClock::now();
  if (iteration > 0 && std::chrono::duration<double>(t0 - volume_at_).count() < o_.volume_every_seconds) return;
  volume_at_ = t0;
  std::vector<float> x(h.shape.ParamCount());
  run_.backend->Download(h.params, x);
  o_.on_volume(MakeCheckpoint(run_.scene, h.level, h.shape, iteration + 1, h.solver.type, std::move(x)), iteration);
  const double seconds = SecondsSince(t0);
  eval_seconds_ += seconds;
  volume_seconds_ += seconds;
}

json LevelMonitor::LevelLine(const SolverSummary& summary) {
  json line{{"event", "level"}, {"level", lr_.level}, {"n", lr_.shape.n}};
  line.update(summary.ToJson());
  line.update({{"iterations", lr_.iterations},
               {"seconds", lr_.seconds},
               {"elapsed", elapsed_},
               {"cost", lr_.cost},
               {"train_psnr", lr_.train_psnr},
               {"test_psnr", lr_.test_psnr},
               {"preview_seconds", preview_seconds_},
               {"volume_seconds", volume_seconds_},
               {"status", lr_.status}});
  if (run_.ranks != nullptr) {
    // Every rank's seconds in its own passes and in the sums (waiting for the slowest included).
    Communicator& comm = run_.comm;
    const size_t n = static_cast<size_t>(comm.size()), me = static_cast<size_t>(comm.rank());
    std::vector<double> seconds(2 * n, 0.0);
    seconds[me] = run_.ranks->pass_seconds() - pass_at_level_;
    seconds[n + me] = run_.ranks->sum_seconds() - sum_at_level_;
    comm.SumInPlace(seconds);
    line["rank_pass_seconds"] = std::vector<double>(seconds.begin(), seconds.begin() + static_cast<ptrdiff_t>(n));
    line["rank_sum_seconds"] = std::vector<double>(seconds.begin() + static_cast<ptrdiff_t>(n), seconds.end());
    line["ranks"] = comm.size();
    line["summed_bytes"] = SummedBytes() - summed_at_level_;
    line["summed_bytes_per_iteration"] =
        summary.iterations > 0 ? (SummedBytes() - summed_at_level_) / summary.iterations : 0;
  }
  return line;
}

double LevelMonitor::EndLevelClock() {
  const double seconds = SecondsSince(t_level_) - eval_seconds_;
  elapsed_ += seconds;
  t_level_ = WallClock::now();
  eval_seconds_ = 0;
  return seconds;
}

}  // namespace perf::recon
