#include "pipeline/run_pipeline.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/json_log.h"
#include "common/owned_files.h"
#include "common/stopwatch.h"
#include "export/evaluate.h"
#include "export/export.h"
#include "pipeline/stage_freshness.h"
#include "pipeline/stage_progress.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/level_choice.h"
#include "recon_cuda/run/reconstruct.h"
#include "recon_cuda/run/time_plan.h"
#include "sfm_import/colmap_runner.h"
#include "sfm_import/ghost_repair.h"
#include "sfm_import/importer.h"
#include "sfm_import/model_check.h"
#include "viewer/live_view.h"

namespace perf {

namespace fs = std::filesystem;

namespace {

constexpr const char* kCommandLine = "command line";

// --log-json: one JSON line per stage event (and reconstruct iteration), stamped with the time;
// nothing without a path.
class StageLog {
 public:
  explicit StageLog(const fs::path& path) {
    if (path.empty()) return;
    if (path.has_parent_path()) EnsureWritableDirectory(path.parent_path());
    log_ = JsonLog(path, true, "--log-json log");
  }
  void Write(nlohmann::json j) {
    j["time"] = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
    log_.Write(j);
  }

 private:
  JsonLog log_;
};

// A rank other than 0: waits for rank 0's sfm and import, then fits its share of the photos;
// rank 0 exports.
void RunAsRank(const RunOptions& o) {
  o.comm->Barrier();
  recon::Reconstruct(o.ReconstructStage(PresetFor(o)));
}

class Runner {
 public:
  Runner(const RunOptions& o, RunResult* r, WallClock::time_point start)
      : o_(o), r_(r), log_(o.log_json), preset_(PresetFor(o)), start_(start) {}

  void Run() {
    Say("preset " + o_.preset + ": " + preset_.Describe());
    const bool gpu = o_.device == recon::DeviceChoice::kCuda ||
                     (o_.device == recon::DeviceChoice::kAuto && recon::CudaDeviceAvailable(nullptr));
    r_->time_budget = o_.time_budget ? *o_.time_budget : DefaultTimeBudget(o_.preset, gpu);
    r_->time_budget_from = o_.time_budget ? "--time-budget" : StrCat("the ", o_.preset, " preset's on a ", gpu ? "GPU" : "CPU");
    if (r_->time_budget > 0) {
      Say(StrCat("time budget: ", r_->time_budget, " s for the whole run (", r_->time_budget_from,
                 "); the reconstruction plans its levels and iterations to fit"));
    }
    fs::path model = o_.colmap;
    if (o_.nerf.empty() && model.empty()) {
      Stage("sfm", [&](StageReport* s) { model = Sfm(s); });
    }
    Stage("import", [&](StageReport* s) { Import(model, s); });
    Stage("reconstruct", [&](StageReport* s) { Reconstruct(s); });
    Stage("export", [&](StageReport* s) { Export(s); });
    Stage("eval", [&](StageReport* s) { Eval(s); });
  }

 private:
  template <class F>
  void Stage(const std::string& name, F&& body) {
    StageReport s;
    s.name = name;
    const auto start = WallClock::now();
    log_.Write({{"stage", name}, {"event", "start"}});
    if (o_.live != nullptr) o_.live->Stage(name);
    try {
      body(&s);
    } catch (const Interrupted&) {
      log_.Write({{"stage", name}, {"event", "interrupted"}, {"seconds", SecondsSince(start)}});
      throw;
    } catch (const std::exception& e) {
      log_.Write({{"stage", name}, {"event", "failed"}, {"error", e.what()}});
      throw;
    }
    s.seconds = SecondsSince(start);
    log_.Write({{"stage", name}, {"event", s.skipped ? "skipped" : "done"}, {"reason", s.reason}, {"seconds", s.seconds}});
    if (s.skipped) Say(name + ": skipped (" + s.reason + ")");
    r_->stages.push_back(s);
  }

  void Say(const std::string& line) {
    if (!o_.quiet) std::cout << line << "\n" << std::flush;
  }

  void CheckStop() const {
    if (o_.stop != nullptr && o_.stop->load()) {
      throw Interrupted("the workspace is consistent; run the same command again to resume");
    }
  }

  fs::path Sfm(StageReport* s) {
    const fs::path sparse = o_.workspace / "sparse" / "0";
    if (!o_.force && !fs::exists(sparse / "cameras.bin") && fs::exists(sparse / "cameras.txt")) {
      s->skipped = true;  // a text model put there by hand (perf's runs write binary ones)
      s->reason = "sparse/0 holds a text model";
      return sparse;
    }
    SfmOptions so;
    so.images = o_.images;
    so.workspace = o_.workspace;
    so.force = o_.force;
    so.check_stop = [&] { CheckStop(); };
    so.check_model = ObjectModelDoubtOf;
    so.seconds_left = SecondsLeft();
    so.progress = [&](const std::string& line) {
      CheckStop();
      Say(line.rfind("sfm: ", 0) == 0 ? line : "sfm: " + line);  // RunSfm's own lines already say so
    };
    // RunSfm keeps a model at sparse/0 made from these photos (and says so), or makes it again.
    const SfmResult r = RunSfm(so);
    s->skipped = r.kept;
    s->reason = r.kept ? "sparse/0 exists" : StrCat(r.num_registered_images, " of ", r.num_input_images, " photos registered");
    return r.sparse_dir;
  }

  void Import(fs::path model, StageReport* s) {
    fs::path images = o_.images;
    std::vector<std::vector<std::string>> turn_unknown;
    if (!o_.colmap.empty()) {  // the user's model (perf sfm's own is not made again)
      RepairOptions ro;
      ro.model = model;
      ro.images = o_.images;
      ro.workspace = o_.workspace;
      ro.repair = o_.repair;
      ro.threads = o_.threads;
      ro.say = [&](const std::string& line) { Say("import: " + line); };
      ro.check_stop = [&] { CheckStop(); };
      ro.seconds_left = SecondsLeft();
      const RepairResult repaired = RepairModel(ro);
      r_->repair = repaired.ToJson();
      model = repaired.model;
      if (repaired.used) images = repaired.images;
      turn_unknown = repaired.TurnUnknown();
    }
    const fs::path input = o_.nerf.empty() ? model : o_.nerf;
    const fs::path scene = o_.workspace / "scene.json";
    // A photo replaced or edited since the import counts as a newer input too.
    const auto newest = o_.nerf.empty() ? std::max(NewestInput(input), NewestUnder(images)) : NewestInput(input);
    if (!o_.force && NewerThan(scene, newest)) {
      const std::string changed = ImportChanges(scene, {o_.nerf.empty(), input, images, preset_.max_size,
                                                        o_.keep_bad_poses});
      if (changed.empty()) {
        s->skipped = true;
        s->reason = "scene.json is newer than " + input.string() + (o_.nerf.empty() ? " and the photos" : "");
        return;
      }
      Say("import: " + changed + ": importing again");
    }
    RefuseReplacingAnEditedScene(scene);
    const std::vector<std::string> by_hand = ExcludedByHand(scene);  // in a scene.json a reconstruct wrote back
    ImportOptions io;
    if (o_.nerf.empty()) {
      io.colmap_dir = model;
      io.images_dir = images;
    } else {
      io.nerf_json = o_.nerf;
    }
    io.workspace = o_.workspace;
    io.keep_bad_poses = o_.keep_bad_poses;
    io.turn_unknown = std::move(turn_unknown);
    io.max_size = preset_.max_size;
    io.num_threads = o_.threads;
    Progress progress("import", o_.quiet);
    io.progress = [&](int done, int total) {
      CheckStop();
      progress.Update(done, total, "images");
    };
    const ImportResult r = RunImport(io);
    progress.Finish();
    for (const std::string& w : r.warnings) Say("import: warning: " + w);
    std::string dropped;  // left out by hand in the scene.json this import replaced
    for (const SceneImage& im : r.scene.images) {
      if (im.split != Split::kExcluded && std::find(by_hand.begin(), by_hand.end(), im.name) != by_hand.end()) {
        dropped += (dropped.empty() ? "" : ", ") + im.name;
      }
    }
    if (!dropped.empty()) {
      Say("import: warning: the new scene.json trains or scores " + dropped + ", which the old one left out by hand; "
          "set their \"split\" to \"excluded\" again to leave them out");
    }
    s->reason = StrCat(r.scene.images.size(), " images");
  }

  // A scene.json changed since PERF wrote it (photos left out by hand, say) is the user's: a new
  // import would replace it, so it is refused by name, with the photos its edit leaves out.
  static void RefuseReplacingAnEditedScene(const fs::path& scene) {
    std::error_code ec;
    if (!fs::exists(scene, ec) || IsOwned(scene)) return;
    std::string by_hand;
    for (const std::string& name : ExcludedByHand(scene)) by_hand += (by_hand.empty() ? "" : ", ") + name;
    throw InputError(scene.string(), "", "",
                     StrCat("changed since PERF wrote it", by_hand.empty() ? "" : " (it leaves out " + by_hand + " by hand)",
                            ", and importing again would replace it"),
                     "move it away (e.g. to scene.hand.json) and run again; then set the \"split\" of the photos it "
                     "left out to \"excluded\" in the new scene.json");
  }

  void Reconstruct(StageReport* s) {
    recon::ReconstructOptions ro = o_.ReconstructStage(preset_);
    if (r_->time_budget > 0) ro.time_budget = Budget();
    if (o_.comm != nullptr) o_.comm->Barrier();  // the other ranks start from this workspace (RunAsRank)
    Progress progress("reconstruct", o_.quiet);
    ro.on_event = [&](const recon::ReconstructOptions::Event& e) {
      CheckStop();
      ShowReconstructEvent(progress, e);
      if (!e.message.empty()) return;
      if (o_.live != nullptr) o_.live->Iteration(e.level, e.levels, e.iteration, e.iterations);
      log_.Write({{"stage", "reconstruct"}, {"event", "iteration"}, {"level", e.level}, {"iteration", e.iteration},
                  {"iterations", e.iterations}, {"cost", e.cost}, {"train_psnr", e.train_psnr}});
    };
    const recon::ReconstructResult r = recon::Reconstruct(ro);
    progress.Finish();
    r_->final_checkpoint = r.final_checkpoint;
    r_->time_plan = r.time_plan;
    if (r.already_complete) {
      s->skipped = true;
      s->reason = "every level is checkpointed";
    } else if (!r.settings_changed.empty()) {
      s->reason = "from the start: " + r.settings_changed;
    } else {
      s->reason = ro.resume ? "resumed after the last checkpoint" : "from the start";
    }
  }

  void Export(StageReport* s) {
    const auto checkpoint_time = ModTime(r_->final_checkpoint);
    if (!o_.force && NewerThan(o_.workspace / "export.json", checkpoint_time)) {
      const nlohmann::json j = nlohmann::json::parse(ReadFileToString(o_.workspace / "export.json"), nullptr, false);
      // The preset's orbit: another frame count is exported again.
      const int orbit = j.is_object() && j.contains("renders") ? j["renders"].value("orbit", -1) : -1;
      if (orbit == preset_.orbit_frames) {
        s->skipped = true;
        s->reason = "export.json is newer than the checkpoint";
        if (j.contains("masks")) r_->mask_coverage = j["masks"].value("mean_coverage", 0.0);
        return;
      }
    }
    exporter::ExportOptions eo;
    eo.workspace = o_.workspace;
    eo.checkpoint = r_->final_checkpoint;
    eo.orbit.frames = preset_.orbit_frames;
    eo.device = o_.device;
    eo.threads = o_.threads;
    StepProgress progress("export", o_.quiet);
    eo.progress = [&](const std::string& step, int done, int total) {
      CheckStop();
      progress.Update(step, done, total);
    };
    const exporter::ExportResult r = exporter::RunExport(eo);
    progress.Finish();
    r_->mask_coverage = r.mean_mask_coverage;
    if (!r.iso.warning.empty()) Say("export: warning: " + r.iso.warning);
    s->reason = StrCat(r.files.size(), " files");
  }

  void Eval(StageReport* s) {
    const fs::path report = o_.workspace / "report.json";
    if (!o_.force && NewerThan(report, ModTime(r_->final_checkpoint))) {
      s->skipped = true;
      s->reason = "report.json is newer than the checkpoint";
    } else {
      exporter::EvalOptions eo;
      eo.workspace = o_.workspace;
      eo.checkpoint = r_->final_checkpoint;
      eo.device = o_.device;
      eo.threads = o_.threads;
      Progress progress("eval", o_.quiet);
      eo.progress = [&](const std::string&, int done, int total) {
        CheckStop();
        progress.Update(done, total, "images");
      };
      exporter::RunEval(eo);
      progress.Finish();
    }
    const nlohmann::json j = nlohmann::json::parse(ReadFileToString(report), nullptr, false);
    if (j.is_object() && j.contains("mean")) {
      r_->test_psnr = j["mean"].value("psnr", 0.0);
      r_->test_ssim = j["mean"].value("ssim", 0.0);
      if (j.contains("masks")) r_->mask_iou = j["masks"]["pooled"].value("iou", -1.0);
    }
  }

  // The seconds left of the run's time budget, for COLMAP's steps (unset: no budget).
  std::function<double()> SecondsLeft() const {
    if (r_->time_budget <= 0) return {};
    return [deadline = Budget().Deadline()] { return std::chrono::duration<double>(deadline - WallClock::now()).count(); };
  }

  // The budget from the run's start, with export and eval measured as this run will do them.
  recon::TimeBudget Budget() const {
    recon::TimeBudget b;
    b.seconds = r_->time_budget;
    b.start = start_;
    b.after_solve = [this](recon::Backend* backend, recon::VecId params, const Scene& scene) {
      exporter::ExportOptions eo;
      eo.workspace = o_.workspace;
      eo.orbit.frames = preset_.orbit_frames;
      const bool pose_fit = recon::RefinesPoses(o_.poses, scene, recon::SolverType::kGaussNewton);
      return exporter::EstimateExportAndEvalSeconds(backend, params, scene, eo, pose_fit);
    };
    return b;
  }

  const RunOptions& o_;
  RunResult* r_;
  StageLog log_;
  PresetSettings preset_;
  WallClock::time_point start_;
};

}  // namespace

recon::ReconstructOptions RunOptions::ReconstructStage(const PresetSettings& preset) const {
  const int last = recon::LastCheckpointLevel(workspace);
  const bool fresh = last >= 0 && NewerThan(recon::CheckpointPath(workspace, last), ModTime(workspace / "scene.json"));
  recon::ReconstructOptions ro;
  ro.workspace = workspace;
  ro.comm = comm;
  ro.device = device;
  ro.threads = threads;
  ro.levels = preset.levels;
  ro.max_resolution = preset.max_resolution;
  ro.iterations = preset.iterations;
  ro.exposure = exposure;
  ro.poses = poses;
  ro.refine_focal = refine_focal;
  ro.sh_degree = preset.sh_degree;
  ro.sh_from_level = preset.sh_from_level;
  ro.solver.cost_tolerance = cost_tolerance;
  ro.preview_every = live != nullptr ? 1 : 0;  // the live page shows the newest
  if (live != nullptr) {  // and draws the solver's volume
    ro.on_volume = [l = live](recon::Checkpoint volume, int iteration) { l->Volume(std::move(volume), iteration); };
  }
  ro.preview_image = view_image;
  ro.resume = fresh && !force;
  ro.restart_if_settings_changed = true;  // the outputs must be what this command line asks for
  return ro;
}

void RunOptions::Check() const {
  const int sources = !colmap.empty() + !nerf.empty();
  if (sources > 1) throw InputError(kCommandLine, "--colmap/--nerf", "both", "give one source", "use --colmap or --nerf");
  if (sources == 0 && images.empty()) {
    throw InputError(kCommandLine, "--images", "(none)", "no input given",
                     "pass --images DIR (photos), --colmap MODEL (with --images), or --nerf transforms.json");
  }
  if (!nerf.empty() && !images.empty()) {
    throw InputError(kCommandLine, "--images", images.string(), "not used with --nerf (its json names the images)");
  }
  if (preset != "preview" && preset != "default" && preset != "high") {
    throw InputError(kCommandLine, "--preset", preset, "unknown preset", "use preview, default or high");
  }
  if (max_size < 0) throw InputError(kCommandLine, "--max-size", StrCat(max_size), "must be >= 0");
  if (levels < 0 || levels > 6) throw InputError(kCommandLine, "--levels", StrCat(levels), "must be 1 to 6");
  if (iterations < 0) throw InputError(kCommandLine, "--iterations", StrCat(iterations), "must be >= 0");
  if (max_resolution < 0) throw InputError(kCommandLine, "--max-resolution", StrCat(max_resolution), "must be >= 0");
  // The reconstruction's own checks of what perf run passes it, before the import.
  if (sh_degree != -1) recon::CheckShDegree(sh_degree);  // -1: the preset's
  if (sh_from_level) {
    recon::CheckShFromLevel(*sh_from_level);
    const int set_levels = PresetFor(*this).levels;  // 0: from the photos, known after the import
    if (set_levels > 0) recon::ShFromLevelIndex(*sh_from_level, {.levels = set_levels, .automatic = false});
  }
  recon::SolverOptions solver;
  solver.cost_tolerance = cost_tolerance;
  solver.Check();
  recon::CheckCameraRefinement(poses, refine_focal);
  for (const fs::path* p : {&images, &colmap, &nerf}) {
    if (!p->empty() && !fs::exists(*p)) throw IoError(p->string(), "does not exist", "check the path");
  }
  if (!nerf.empty()) CheckRegularFile(nerf);  // a FIFO or a device: named before a workspace is made
}

RunResult RunPipeline(const RunOptions& o) {
  o.Check();
  if (o.comm != nullptr && !o.comm->IsRoot()) {
    RunAsRank(o);
    return {};
  }
  EnsureWritableDirectory(o.workspace);
  const auto start = WallClock::now();
  RunResult r;
  Runner(o, &r, start).Run();
  r.seconds = SecondsSince(start);
  nlohmann::json stages = nlohmann::json::array();
  for (const StageReport& s : r.stages) {
    stages.push_back({{"stage", s.name}, {"skipped", s.skipped}, {"reason", s.reason}, {"seconds", s.seconds}});
  }
  const nlohmann::json summary = {{"format", "perf-run"},
                                  {"version", 1},
                                  {"preset", o.preset},
                                  {"stages", stages},
                                  {"test_psnr", r.test_psnr},
                                  {"test_ssim", r.test_ssim},
                                  {"mask_coverage", r.mask_coverage},
                                  {"seconds", r.seconds},
                                  {"repair", r.repair},
                                  {"time_budget",
                                   {{"seconds", r.time_budget},
                                    {"from", r.time_budget_from},
                                    {"within", r.time_budget <= 0 || r.seconds <= r.time_budget},
                                    {"plan", r.time_plan}}}};
  WriteFileAtomically(o.workspace / "run.json", summary.dump(2) + "\n");
  return r;
}

std::string RunSummary(const RunOptions& o, const RunResult& r) {
  const fs::path ws = o.workspace;
  std::ostringstream s;
  s << std::fixed << std::setprecision(1);
  s << "\nDone in " << r.seconds << " s (";
  for (size_t i = 0; i < r.stages.size(); ++i) {
    s << (i ? ", " : "") << r.stages[i].name << " " << r.stages[i].seconds << " s" << (r.stages[i].skipped ? " skipped" : "");
  }
  s << ")\n";
  s << std::setprecision(2) << "Held-out views: PSNR " << r.test_psnr << " dB, SSIM " << std::setprecision(3) << r.test_ssim
    << std::setprecision(1) << "; masks cover " << 100 * r.mask_coverage << " % of the photos on average";
  if (r.mask_iou >= 0) s << std::setprecision(3) << ", IoU " << r.mask_iou << " against the true masks";
  s << "\nOutputs in " << ws.string() << ":\n"
    << "  masks/binary/, masks/soft/   foreground masks of every photo\n"
    << "  foreground/                  the photos cut out (RGBA PNG)\n"
    << "  volume.vdb                   OpenVDB density + color grids (Blender, Houdini)\n"
    << "  mesh.glb, mesh.obj (+ .mtl, .png)  textured mesh; mesh.ply with vertex colours\n"
    << "  renders/test/, renders/orbit/  held-out views and an orbit\n"
    << "  report.html, report.json     scores, PSNR-vs-time plot, renders next to photos\n";
  return s.str();
}

}  // namespace perf
