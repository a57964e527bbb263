#include "recon_cuda/run/reconstruct.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/owned_files.h"
#include "common/system_memory.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/level_monitor.h"
#include "recon_cuda/run/render_views.h"
#include "recon_cuda/run/reconstruct_run.h"
#include "recon_cuda/run/run_settings.h"
#include "recon_cuda/run/turn_search.h"

namespace perf::recon {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A checkpoint made from another scene (re-imported workspace) must not be resumed.
void CheckMatchesScene(const Checkpoint& c, const Scene& scene, const fs::path& path) {
  const VolumePlacement& p = c.placement;
  double worst = 0;
  for (int a = 0; a < 3; ++a) {
    worst = std::max({worst, std::abs(p.box_center[a] - scene.box.center[a]), std::abs(p.box_size[a] - scene.box.size[a])});
  }
  if (worst > 1e-9 * std::max(1.0, scene.box.size.norm()) || p.shell_radii.size() != scene.shells.radii.size()) {
    throw InputError(path.string(), "box", "", "the checkpoint was made for a different box or shells than scene.json",
                     "the workspace was re-imported; run perf reconstruct without --resume");
  }
}

// Every level's solver memory is checked before anything is allocated or loaded: a level that
// cannot fit fails now, not after the levels before it (--start-resolution 1024 wants ~17 GB).
void CheckLevelsFit(const Backend& backend, const VolumeGeometry& geometry, const HierarchyOptions& ho, int start) {
  // A sparse level's size is known only once the level before it is fitted: SetLevel checks it.
  const int last = ho.sparse ? std::min(start + 1, ho.levels) : ho.levels;
  for (int level = start; level < last; ++level) {
    const LevelProblem problem{LevelShape(ho, geometry.num_shells(), level), geometry, nullptr, ho.residuals, false};
    const MemoryEstimate e = backend.EstimateMemory(problem, RequiredVectors(ho.solver.type));
    // The host also holds the parameters and their resampled copy between levels.
    const int64_t host = 2 * problem.shape.ParamCount() * static_cast<int64_t>(sizeof(float));
    if (e.available > 0 && e.vectors + e.scratch + host > e.available) {
      throw ResourceError(StrCat("level ", level + 1, " (", DescribeShape(problem.shape), ") needs at least ",
                                 FormatByteCount(e.vectors + e.scratch + host), " before its rays, but ",
                                 FormatByteCount(e.available), " are available; use fewer --levels or a smaller "
                                 "--start-resolution"));
    }
  }
}

// The mean colour of every rank's photos (--init-shells-from-photos).
void MeanColour(const std::vector<PosedImage>& images, Communicator& comm, float colour[3]) {
  double sum[4] = {0, 0, 0, 0};  // r, g, b, pixels
  for (const PosedImage& im : images) {
    for (size_t p = 0; p < im.image.pixels.size(); p += 3) {
      for (int c = 0; c < 3; ++c) sum[c] += im.image.pixels[p + c];
    }
    sum[3] += static_cast<double>(im.image.pixels.size() / 3);
  }
  comm.SumInPlace(sum);
  for (int c = 0; c < 3; ++c) colour[c] = sum[3] > 0 ? static_cast<float>(sum[c] / sum[3]) : -1.f;
}

// Every rank must read the same scene.json: a digest of its bytes compared across ranks.
void CheckSameScene(Communicator& comm, const fs::path& scene_path) {
  if (comm.size() == 1) return;
  std::ifstream in(scene_path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const double digest = static_cast<double>(std::hash<std::string>{}(bytes) & ((uint64_t{1} << 52) - 1));
  if (!comm.Agree(digest)) {
    throw InputError(scene_path.string(), "contents", "", StrCat("rank ", comm.rank(), " reads a scene.json that differs "
                     "from another rank's"), "every rank must see the same workspace (a shared file system, or "
                     "identical copies)");
  }
}

// `perf reconstruct` as a controller (COLMAP's IncrementalPipeline shape): Run() is the steps in
// order, each a method; the hierarchy's callbacks are LevelMonitor's.
class Reconstruction {
 public:
  explicit Reconstruction(const ReconstructOptions& o) : run_(o), o_(o) {}

  ReconstructResult Run() {
    o_.Check();
    ReadScene();
    SetUpBackend();
    ChooseHierarchy();
    HierarchyStart start;
    if (!FindStart(&start)) return std::move(run_.result);  // every level is done
    CheckCanFit(start.level);
    LoadPhotos(start.level);
    Describe();
    if (start.level == 0 && o_.init_shells_from_photos) MeanColour(run_.train, run_.comm, run_.hierarchy.init.shell_colour);
    if (start.level == 0) {
      for (const TurnSearch& t : SearchTurns(run_, o_.turn_search)) run_.result.turn_search.push_back(t.ToJson());
    }
    Fit(std::move(start));
    ChooseFinalLevel();
    run_.result.hierarchy = run_.hierarchy;
    if (!run_.result.already_complete && run_.root) {
      WriteFileAtomically(o_.workspace / "recon" / "recon.json", run_.result.ToJson(o_).dump(2) + "\n");
    }
    return std::move(run_.result);
  }

 private:
  // scene.json, the same on every rank, and the volume's placement from it.
  void ReadScene() {
    run_.scene_path = o_.workspace / "scene.json";
    // Written back with the box grown or the cameras refined, keeping what a user edited in it.
    ReadBackAsOwned(run_.scene_path, [&] { run_.scene = perf::ReadScene(run_.scene_path); });
    CheckSameScene(run_.comm, run_.scene_path);
    run_.geometry = VolumeGeometry::FromScene(run_.scene);
  }

  // The backend (--device), and with several ranks the one that sums its passes across them.
  void SetUpBackend() {
    Communicator& comm = run_.comm;
    run_.backend = MakeBackend(o_.device, o_.threads, LocalRank());
    if (comm.size() > 1) {
      if (run_.backend->kind() == BackendKind::kCuda && o_.device_comm) run_.device_comm = o_.device_comm(comm);
      auto d = std::make_unique<DistributedBackend>(std::move(run_.backend),
                                                    run_.device_comm ? run_.device_comm.get() : &comm);
      run_.ranks = d.get();
      run_.backend = std::move(d);
    }
    run_.result.backend = run_.backend->Describe();
    run_.result.ranks = comm.size();
  }

  // How many levels (level_choice.h) and the hierarchy's options for this scene.
  void ChooseHierarchy() {
    ReconstructResult& result = run_.result;
    run_.train_views = SplitViews(run_.scene, Split::kTrain);
    for (const SceneImage& im : run_.scene.images) {
      if (im.split == Split::kTrain) run_.train_names.push_back(im.name);
      if (im.split == Split::kExcluded) result.excluded_views.push_back({{"name", im.name}, {"because", im.excluded_because}});
    }
    result.levels_choice =
        ChooseLevels(o_.levels, PixelsAcrossBox(run_.train_views, run_.geometry), o_.start_resolution,
                     o_.max_resolution > 0 ? o_.max_resolution : DefaultMaxResolution(run_.backend->kind()));
    run_.levels = result.levels_choice.levels;
    run_.hierarchy = o_.Hierarchy(run_.scene, result.levels_choice);
    result.fixed_background = run_.hierarchy.fixed_background;
    result.exposures = run_.hierarchy.exposures;
  }

  // Level 0, or with --resume the level after the last checkpoint; false when every level is done.
  bool FindStart(HierarchyStart* start) {
    Communicator& comm = run_.comm;
    if (run_.root) {
      EnsureWritableDirectory(o_.workspace / "recon");
      RecoverPreviousRun(o_.workspace);
    }
    comm.Barrier();  // the other ranks read the checkpoints rank 0 has put back
    const int last = LastCheckpointLevel(o_.workspace);
    if (!comm.Agree(last) || !comm.Agree(o_.resume ? 1 : 0)) {
      throw InputError((o_.workspace / "recon").string(), "checkpoints", StrCat("last level ", last),
                       StrCat("rank ", comm.rank(), " sees other checkpoints than another rank"),
                       "every rank must see the same workspace (a shared file system)");
    }
    if (!o_.resume || last < 0 || !ResumesTheSameFit()) return true;
    const HierarchyOptions& ho = run_.hierarchy;
    const fs::path path = CheckpointPath(o_.workspace, last);
    Checkpoint c = ReadCheckpoint(path);
    CheckMatchesScene(c, run_.scene, path);
    const VolumeShape expected = LevelShape(ho, run_.geometry.num_shells(), last);
    // (m may be below the ladder's: HierarchyOptions::min_rays_per_texel.)
    if (c.shape.n != expected.n || c.shape.m > expected.m || c.shape.num_shells != expected.num_shells ||
        c.level != last) {
      throw InputError(path.string(), "n", std::to_string(c.shape.n),
                       StrCat("level ", last, " of this run would be ", expected.n, "^3"),
                       "resume with the same --start-resolution, or run without --resume");
    }
    if (last + 1 >= run_.levels) {
      run_.result.already_complete = true;
      run_.result.final_checkpoint = FinalCheckpointPath(o_.workspace);  // as the run that wrote them chose
      run_.Say(StrCat("all ", run_.levels, " levels are done (", path.string(), "); nothing to resume"));
      return false;
    }
    start->level = last + 1;
    start->shape = NextLevelShape(ho, run_.geometry, c.shape, c.params, run_.train_views, last + 1);
    start->x = Resample(c.shape, c.params, start->shape);
    // Constants of this run, whatever an earlier run (perhaps with learned shells) left there.
    if (ho.fixed_background) SetBackgroundShells(start->shape, ho.background.data(), start->x);
    run_.Say(StrCat("resuming after level ", last, " (", path.string(), ")"));
    return true;
  }

  // Whether the checkpoints to resume were fitted with these settings (recon/settings.json). When
  // not, perf run (restart_if_settings_changed) starts over and perf reconstruct --resume
  // continues; either says what changed. Rank 0 reads the record; every rank takes its answer.
  bool ResumesTheSameFit() {
    std::string why;
    if (run_.root) {
      const std::optional<nlohmann::json> before = ReadRunSettings(o_.workspace);
      std::string changes;
      if (before) {
        for (const std::string& c : SettingsChanges(*before, RunSettings(o_))) changes += (changes.empty() ? "" : ", ") + c;
      }
      if (!before) why = "the checkpoints' settings are not recorded (an older perf made them)";
      if (!changes.empty()) why = "the checkpoints' settings differ from this run's (" + changes + ")";
    }
    if (!run_.comm.Any(!why.empty())) return true;
    run_.result.settings_changed = why;
    if (o_.restart_if_settings_changed) {
      run_.Say("fitting from the start: " + why);
      return false;
    }
    run_.Say("resuming although " + why + "; the levels done keep theirs");
    return true;
  }

  // What can be known to fail before the photos are loaded.
  void CheckCanFit(int start_level) {
    CheckLevelsFit(*run_.backend, run_.geometry, run_.hierarchy, start_level);
    const size_t train_views = run_.train_views.size();
    if (train_views == 0) {
      throw InputError(run_.scene_path.string(), "images", "0 train images", "nothing to reconstruct from",
                       "re-run perf import with --holdout 0 or more images");
    }
    if (static_cast<size_t>(run_.comm.size()) > train_views) {
      throw InputError("mpirun", "-np", std::to_string(run_.comm.size()),
                       StrCat("more ranks than the ", train_views, " training photos"),
                       StrCat("run at most ", train_views, " ranks"));
    }
  }

  // This rank's share of the photos; a fresh start puts the earlier run's files aside (kept until
  // this run has a level of its own, and put back if it fails before), and the log.
  void LoadPhotos(int start_level) {
    Communicator& comm = run_.comm;
    run_.Say(comm.size() > 1 ? StrCat("loading images (", comm.Describe(), ": each loads its share of the photos)")
                             : std::string("loading images"));
    const ImageShare share{comm.rank(), comm.size()};
    run_.train = LoadImages(run_.scene, o_.workspace, Split::kTrain, {}, share);
    run_.test = LoadImages(run_.scene, o_.workspace, Split::kTest, {}, share);
    run_.test_views = static_cast<int64_t>(SplitViews(run_.scene, Split::kTest).size());
    run_.preview = run_.test.empty() ? (run_.train.empty() ? nullptr : &run_.train.front()) : &run_.test.front();
    for (const auto* views : {&run_.test, &run_.train}) {
      for (const PosedImage& v : *views) {
        if (v.name == o_.preview_image) run_.preview = &v;
      }
    }
    const bool chosen = run_.preview != nullptr && run_.preview->name == o_.preview_image;
    if (!o_.preview_image.empty() && !chosen && run_.root && comm.size() == 1) {
      throw InputError((o_.workspace / "scene.json").string(), "--view-image", o_.preview_image,
                       "no training or held-out photo of that name", "use an image name from scene.json");
    }
    if (start_level == 0 && run_.root) {
      run_.previous.emplace(o_.workspace);
      WriteFileAtomically(RunSettingsPath(o_.workspace), RunSettings(o_).dump(2) + "\n");
    }
    if (run_.root) run_.log = JsonLog(o_.workspace / "recon" / "log.jsonl", start_level > 0, "reconstruction log");
    if (start_level > 0) run_.log.Write({{"event", "resume"}, {"level", start_level}});
  }

  // The run's settings, for the terminal (and the opacity residual, for recon.json).
  void Describe() {
    ReconstructResult& result = run_.result;
    const Scene& scene = run_.scene;
    run_.Say(StrCat("backend: ", result.backend, "; ", run_.train_views.size(), " training and ", run_.test_views,
                    " held-out views",
                    result.excluded_views.empty()
                        ? std::string()
                        : StrCat(" (", result.excluded_views.size(), " left out on import: scene.json says why)"),
                    "; ", run_.levels, " levels from ", o_.start_resolution, "^3"));
    run_.Say(result.levels_choice.Describe());
    if (run_.hierarchy.exposures > 0) {
      run_.Say(StrCat("exposures: a gain and an offset per channel for each of the ", run_.hierarchy.exposures,
                      " training photos; held-out views take the blend of their two nearest training photos'"));
    }
    // As every level's RaySet will (every rank's photos: either all have alpha or the scene's do not).
    const bool fits_alpha = o_.residuals.use_alpha && !run_.comm.Any(!ImagesHaveAlpha(run_.train));
    result.opacity_weight = OpacityResidualWeight(o_.residuals, fits_alpha);
    result.opacity_residual = result.opacity_weight <= 0 ? "off" : (fits_alpha ? "alpha" : "auxiliary");
    run_.Say(StrCat("opacity residual (weight ", result.opacity_weight, "): ",
                    result.opacity_residual == "alpha" ? "the box opacity fits the photos' alpha"
                    : result.opacity_residual == "off" ? "off"
                                                       : "the paper's auxiliary term (0 or 1)"));
    run_.Say(result.fixed_background
                 ? StrCat("background: fixed at (", scene.background[0], ", ", scene.background[1], ", ",
                          scene.background[2], ")",
                          o_.background == BackgroundChoice::kAuto ? ", the colour every photo's alpha was composited over"
                                                                   : "")
                 : std::string("background: learned (environment shells)"));
  }

  // The hierarchy; where the first level's density goes on beyond the box, the box grows there
  // (every rank alike, from the same fit), scene.json gets it, and the first level is fitted again.
  void Fit(HierarchyStart start) {
    const TrainingViews views = ViewsForHierarchy(run_.train, &run_.comm, run_.train_views);
    LevelMonitor monitor(run_);
    const HierarchyCallbacks cb = monitor.Callbacks();
    for (;;) {
      SolveHierarchy(run_.backend.get(), run_.geometry, views, run_.hierarchy, std::move(start), cb);
      if (monitor.faces_to_grow().empty()) break;
      const BoxGrowth growth = GrowBox(&run_.scene, monitor.box_faces(), monitor.faces_to_grow());
      run_.geometry = VolumeGeometry::From(growth.grown, run_.scene_path.string());
      if (run_.root) WriteScene(run_.scene_path, run_.scene);
      run_.result.box_growths.push_back(growth.ToJson());
      run_.log.Write({{"event", "box_grown"}, {"growth", growth.ToJson()}});
      run_.Say(growth.Message());
      monitor.BoxGrown();
      start = HierarchyStart{};
    }
  }

  // A finer level that scored worse on the held-out views than a coarser one of this run is not
  // what the outputs come from: the best one is final, and the run says so.
  void ChooseFinalLevel() {
    ReconstructResult& result = run_.result;
    const int best = FinalLevelIndex(result.levels, run_.test_views > 0);
    if (best < 0 || best + 1 == static_cast<int>(result.levels.size())) return;
    const LevelReport& chosen = result.levels[best];
    const LevelReport& finest = result.levels.back();
    result.final_checkpoint = CheckpointPath(o_.workspace, chosen.level);
    result.test_psnr = chosen.test_psnr;
    result.final_choice = StrCat("level ", finest.level + 1, " (", finest.shape.n, "^3) scored ", finest.test_psnr,
                                 " dB on the held-out views, below level ", chosen.level + 1, "'s ", chosen.test_psnr,
                                 " dB: export and eval use level ", chosen.level + 1, " (",
                                 fs::relative(result.final_checkpoint, o_.workspace).string(),
                                 "); fewer --levels or a smaller --max-resolution skips the finer one next time");
    run_.log.Write({{"event", "final_level"}, {"level", chosen.level}, {"why", result.final_choice}});
    run_.Say("warning: " + result.final_choice);
  }

  ReconstructRun run_;
  const ReconstructOptions& o_;
};

}  // namespace

int FinalLevelIndex(const std::vector<LevelReport>& levels, bool scored) {
  const int n = static_cast<int>(levels.size());
  if (n == 0 || !scored) return n - 1;
  int best = n - 1;
  for (int k = n - 2; k >= 0; --k) {
    if (levels[k].test_psnr > levels[best].test_psnr) best = k;
  }
  return best;
}

json LevelReport::ToJson(const fs::path& workspace) const {
  return {{"level", level},
          {"n", shape.n},
          {"m", shape.m},
          {"bricks", shape.StoredBricks()},
          {"image_downscale", image_downscale},
          {"rays", rays},
          {"iterations", iterations},
          {"seconds", seconds},
          {"cost", cost},
          {"train_psnr", train_psnr},
          {"test_psnr", test_psnr},
          {"status", status},
          {"checkpoint", fs::relative(CheckpointPath(workspace, level), workspace).string()}};
}

json ReconstructResult::ToJson(const ReconstructOptions& o) const {
  json levels_json = json::array();
  for (const LevelReport& l : levels) levels_json.push_back(l.ToJson(o.workspace));
  const HierarchyOptions& ho = hierarchy;
  return json{{"format", "perf-recon"},
              {"version", 1},
              {"backend", backend},
              {"ranks", ranks},
              {"solver", SolverName(o.solver.type)},
              {"smooth_grid", ho.solver.smooth_grid},
              {"smooth_shells", ho.solver.smooth_shells},
              {"cost_tolerance", ho.solver.cost_tolerance},  // each level's "status" says whether it stopped
              {"background", fixed_background ? "fixed" : "learned"},
              {"sh_degree", o.sh_degree},
              {"sh_from_level", ho.sh_from_level + 1},  // the level the bands joined, 1-based
              {"exposures",
               {{"photos", exposures},
                {"prior", ho.solver.exposure_prior},
                {"gain_range", {gain_range[0], gain_range[1]}},
                {"held_out", exposures > 0 ? "the inverse-distance blend of the two nearest training photos' (camera centres)"
                                           : "none"}}},
              {"poses",
               {{"photos", ho.poses},
                {"from_level", ho.refine_poses_from + 1},
                {"focal", ho.refine_focal},
                {"prior", ho.solver.pose_prior},
                {"held_out", ho.poses > 0 ? "the inverse-distance blend of the two nearest training photos' corrections"
                                          : "as imported"},
                {"warning", pose_warning},
                {"corrections", pose_corrections}}},
              {"robust_scale", o.residuals.robust_scale},
              {"robust_from_level", ho.robust_from_level + 1},
              {"opacity_residual", opacity_residual},
              {"opacity_residual_weight", opacity_weight},
              {"init_opacity", o.init.box_opacity},
              {"min_box_opacity", o.min_box_opacity},  // the render rule of test_psnr
              {"levels", levels_choice.levels},
              {"start_resolution", o.start_resolution},
              {"pixels_across_box", levels_choice.pixels_across_box},
              {"levels_chosen", levels_choice.automatic ? "from the photos" : "as given"},
              {"max_resolution", levels_choice.max_resolution},
              {"levels_note", levels_choice.Describe()},
              {"memory_stop", memory_stop},
              {"time_plan", time_plan},
              {"turn_search", turn_search},
              {"iterations_per_level", o.iterations},
              {"level_iterations", o.level_iterations},
              {"excluded_views", excluded_views},
              {"photo_fits", photo_fits},
              {"box_faces", box_faces},
              {"box_warning", box_warning},
              {"box_growths", box_growths},
              {"final_checkpoint", fs::relative(final_checkpoint, o.workspace).string()},
              {"final_choice", final_choice},
              {"test_psnr", test_psnr},
              {"solve_seconds", solve_seconds},
              {"levels_run", levels_json}};
}

TrainingViews ViewsForHierarchy(const std::vector<PosedImage>& train, Communicator* comm,
                                std::vector<ViewFrustum> all_views) {
  TrainingViews views;
  views.views = std::move(all_views);
  if (views.views.empty()) {
    for (const PosedImage& im : train) views.views.push_back({im.camera, im.image.width, im.image.height});
  }
  views.rays = [&train, comm](int factor) {
    RaySet rays;
    if (factor == 1) {
      rays = MakeRaySet(train);
    } else {
      rays = MakeRaySet(DownscaledAll(train, factor));
    }
    if (comm != nullptr) {  // collectives: every rank calls both
      rays.first_index = comm->ShareOf(rays.size()).first;
      const int64_t first_image = comm->ShareOf(static_cast<int64_t>(train.size())).first;
      for (int32_t& slot : rays.exposure_slot) slot += static_cast<int32_t>(first_image);
    }
    return rays;
  };
  return views;
}

ReconstructResult Reconstruct(const ReconstructOptions& options) { return Reconstruction(options).Run(); }

std::string ReconstructSummary(const ReconstructResult& r) {
  std::ostringstream s;
  s.precision(4);
  if (r.already_complete) {
    s << "reconstruction already complete: " << r.final_checkpoint.string() << "\n";
    return s.str();
  }
  s << "reconstructed on " << r.backend << " in " << r.solve_seconds << " s";
  if (r.test_psnr > 0) s << ", held-out PSNR " << r.test_psnr << " dB";
  s << "\n  final checkpoint: " << r.final_checkpoint.string() << "\n";
  return s.str();
}

}  // namespace perf::recon
