#include "recon_cuda/reconstruct.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <optional>
#include <nlohmann/json.hpp>
#include <sstream>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/json_log.h"
#include "common/stopwatch.h"
#include "common/system_memory.h"
#include "recon_cuda/box_check.h"
#include "recon_cuda/checkpoint.h"
#include "recon_cuda/distributed_backend.h"
#include "recon_cuda/evaluation.h"
#include "recon_cuda/hierarchy.h"
#include "recon_cuda/previous_run.h"
#include "workspace/image_io.h"

namespace perf::recon {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

void Fail(const char* option, const std::string& value, const std::string& problem, const std::string& hint = {}) {
  throw InputError("command line", option, value, problem, hint);
}

json IterationJson(const LevelReport& lr, const SolverOptions& so, const IterationSummary& s, double elapsed) {
  return json{{"event", "iteration"},
              {"level", lr.level},
              {"n", lr.shape.n},
              {"solver", SolverName(so.type)},
              {"iteration", s.iteration},
              {"cost", s.cost},
              {"cost_after", s.cost_after},
              {"train_psnr", s.train_psnr},
              {"cg_iterations", s.cg_iterations},
              {"held", s.held},
              {"step", s.step},
              {"line_search_steps", s.line_search_steps},
              {"accepted", s.accepted},
              {"rays", lr.rays},
              {"samples", s.samples},
              {"elapsed", elapsed},
              {"seconds",
               {{"linearize", s.seconds_linearize},
                {"cg", s.seconds_cg},
                {"line_search", s.seconds_line_search},
                {"update", s.seconds_update},
                {"psnr", s.seconds_psnr},
                {"total", s.seconds_total}}}};
}

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

}  // namespace

void ReconstructOptions::Check() const {
  if (workspace.empty()) Fail("WORKSPACE", "", "missing", "pass the workspace made by perf import");
  if (levels < 0 || levels > 6) Fail("--levels", std::to_string(levels), "must be 1 to 6 (or 0 for the default)");
  if (!(smooth_shells >= 0 && std::isfinite(smooth_shells))) {
    Fail("--smooth-shells", StrCat(smooth_shells), "must be finite and >= 0 (0: off)");
  }
  if (!std::isfinite(smooth_grid)) Fail("--smooth-grid", StrCat(smooth_grid), "must be finite (0: off)");
  if (sh_degree < 0 || sh_degree > 2) Fail("--sh-degree", std::to_string(sh_degree), "must be 0, 1 or 2");
  if (max_resolution != 0 && max_resolution < start_resolution) {
    Fail("--max-resolution", std::to_string(max_resolution), StrCat("must be at least --start-resolution (", start_resolution, ")"),
         "or 0 for the backend's default");
  }
  if (start_resolution < 2 || start_resolution > 1024) {
    Fail("--start-resolution", std::to_string(start_resolution), "must be 2 to 1024");
  }
  if (iterations < 0) Fail("--iterations", std::to_string(iterations), "must be >= 0");
  for (int i : level_iterations) {
    if (i < 0) Fail("--level-iterations", std::to_string(i), "must be >= 0 for every level");
  }
  if (preview_every < 0) Fail("--preview-every", std::to_string(preview_every), "must be >= 0");
  if (eval_every < 0) Fail("--eval-every", std::to_string(eval_every), "must be >= 0");
  if (!(residuals.lambda >= 0)) Fail("--lambda", StrCat(residuals.lambda), "must be >= 0");
  if (!(residuals.alpha_weight >= 0)) Fail("--alpha-weight", StrCat(residuals.alpha_weight), "must be >= 0");
  if (!(residuals.robust_scale >= 0 && std::isfinite(residuals.robust_scale))) {
    Fail("--robust", StrCat(residuals.robust_scale), "must be >= 0 (0: least squares)");
  }
  if (!(residuals.stop_transmittance >= 0 && residuals.stop_transmittance < 1)) {
    Fail("--stop-transmittance", StrCat(residuals.stop_transmittance), "must be in [0, 1)");
  }
  if (!(init.box_opacity >= 0 && init.box_opacity < 1)) {
    Fail("--init-opacity", StrCat(init.box_opacity), "must be in [0, 1)", "0.99 is the default; 0.05 a nearly clear start");
  }
  if (!(min_box_opacity >= 0 && min_box_opacity <= 1)) {
    Fail("--min-box-opacity", StrCat(min_box_opacity), "must be in [0, 1]");
  }
  solver.Check();
}

namespace {

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

HierarchyOptions ToHierarchy(const ReconstructOptions& o, int levels) {
  HierarchyOptions h;
  h.levels = levels;
  h.start_resolution = o.start_resolution;
  h.iterations = o.iterations;
  h.level_iterations = o.level_iterations;
  h.solver = o.solver;
  h.init = o.init;
  h.residuals = o.residuals;
  h.pyramid = o.pyramid;
  h.sparse = !o.dense;
  h.occupancy = o.occupancy;
  return h;
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

}  // namespace

bool FixedBackground(BackgroundChoice background, const Scene& scene) {
  return background == BackgroundChoice::kAuto ? EveryImageHasAlpha(scene) : background == BackgroundChoice::kFixed;
}

bool SolvesExposures(ExposureChoice exposure, const Scene& scene) {
  return exposure == ExposureChoice::kOn || (exposure == ExposureChoice::kAuto && scene.source.type == "colmap");
}

void SetHierarchyBackground(BackgroundChoice background, const Scene& scene, HierarchyOptions* options) {
  options->fixed_background = FixedBackground(background, scene);
  options->background = {static_cast<float>(scene.background.x()), static_cast<float>(scene.background.y()),
                         static_cast<float>(scene.background.z())};
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
      std::vector<PosedImage> small;
      for (const PosedImage& im : train) small.push_back(Downscaled(im, factor));
      rays = MakeRaySet(small);
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

ReconstructResult Reconstruct(const ReconstructOptions& o) {
  o.Check();
  SingleProcess single;
  Communicator& comm = o.comm != nullptr ? *o.comm : single;
  const bool root = comm.IsRoot();  // writes the workspace and reports
  const auto emit = [&](const ReconstructOptions::Event& e) {
    if (o.on_event && root) o.on_event(e);
  };
  const auto say = [&](const std::string& line) {
    ReconstructOptions::Event e;
    e.message = line;
    emit(e);
  };

  const fs::path scene_path = o.workspace / "scene.json";
  Scene scene = ReadScene(scene_path);  // its box grows where the object goes on (grow_box)
  CheckSameScene(comm, scene_path);
  VolumeGeometry geometry = VolumeGeometry::FromScene(scene);
  std::unique_ptr<Backend> backend = MakeBackend(o.device, o.threads, LocalRank());
  DistributedBackend* ranks = nullptr;  // with several ranks: sums the passes across them
  std::unique_ptr<Communicator> device_comm;  // NCCL, for a CUDA backend
  if (comm.size() > 1) {
    if (backend->kind() == BackendKind::kCuda && o.device_comm) device_comm = o.device_comm(comm);
    auto d = std::make_unique<DistributedBackend>(std::move(backend), device_comm ? device_comm.get() : &comm);
    ranks = d.get();
    backend = std::move(d);
  }
  ReconstructResult result;
  result.backend = backend->Describe();
  result.ranks = comm.size();
  const std::vector<ViewFrustum> train_views = SplitViews(scene, Split::kTrain);
  result.levels_choice = ChooseLevels(o.levels, PixelsAcrossBox(train_views, geometry), o.start_resolution,
                                      o.max_resolution > 0 ? o.max_resolution : DefaultMaxResolution(backend->kind()));
  const int levels = result.levels_choice.levels;
  HierarchyOptions ho = ToHierarchy(o, levels);
  ho.stop_when_out_of_memory = result.levels_choice.automatic;
  SetHierarchyBackground(o.background, scene, &ho);
  result.fixed_background = ho.fixed_background;
  ho.solver.smooth_grid = o.smooth_grid >= 0 ? o.smooth_grid : ho.fixed_background ? 0.0 : kAutoSmoothGrid;
  ho.solver.smooth_shells = o.smooth_shells;
  if (o.solver.type == SolverType::kAdam) ho.solver.smooth_grid = ho.solver.smooth_shells = 0;  // Gauss-Newton only
  ho.exposures = SolvesExposures(o.exposure, scene) ? static_cast<int>(train_views.size()) : 0;
  ho.sh_degree = o.sh_degree;
  result.exposures = ho.exposures;
  const auto shape_of = [&](int level) { return LevelShape(ho, geometry.num_shells(), level); };

  if (root) {
    EnsureWritableDirectory(o.workspace / "recon");
    RecoverPreviousRun(o.workspace);
  }
  comm.Barrier();  // the other ranks read the checkpoints rank 0 has put back
  HierarchyStart start;
  const int last = LastCheckpointLevel(o.workspace);
  if (!comm.Agree(last) || !comm.Agree(o.resume ? 1 : 0)) {
    throw InputError((o.workspace / "recon").string(), "checkpoints", StrCat("last level ", last),
                     StrCat("rank ", comm.rank(), " sees other checkpoints than another rank"),
                     "every rank must see the same workspace (a shared file system)");
  }
  if (o.resume && last >= 0) {
    const fs::path path = CheckpointPath(o.workspace, last);
    Checkpoint c = ReadCheckpoint(path);
    CheckMatchesScene(c, scene, path);
    const VolumeShape expected = shape_of(last);
    // (m may be below the ladder's: HierarchyOptions::min_rays_per_texel.)
    if (c.shape.n != expected.n || c.shape.m > expected.m || c.shape.num_shells != expected.num_shells ||
        c.level != last) {
      throw InputError(path.string(), "n", std::to_string(c.shape.n),
                       StrCat("level ", last, " of this run would be ", shape_of(last).n, "^3"),
                       "resume with the same --start-resolution, or run without --resume");
    }
    if (last + 1 >= levels) {
      result.already_complete = true;
      result.final_checkpoint = path;
      say(StrCat("all ", levels, " levels are done (", path.string(), "); nothing to resume"));
      return result;
    }
    start.level = last + 1;
    start.shape = NextLevelShape(ho, geometry, c.shape, c.params, train_views);
    start.x = Resample(c.shape, c.params, start.shape);
    // Constants of this run, whatever an earlier run (perhaps with learned shells) left there.
    if (result.fixed_background) SetBackgroundShells(start.shape, ho.background.data(), start.x);
    say(StrCat("resuming after level ", last, " (", path.string(), ")"));
  }

  CheckLevelsFit(*backend, geometry, ho, start.level);
  if (train_views.empty()) {
    throw InputError(scene_path.string(), "images", "0 train images", "nothing to reconstruct from",
                     "re-run perf import with --holdout 0 or more images");
  }
  if (static_cast<size_t>(comm.size()) > train_views.size()) {
    throw InputError("mpirun", "-np", std::to_string(comm.size()),
                     StrCat("more ranks than the ", train_views.size(), " training photos"),
                     StrCat("run at most ", train_views.size(), " ranks"));
  }
  say(comm.size() > 1 ? StrCat("loading images (", comm.Describe(), ": each loads its share of the photos)")
                      : std::string("loading images"));
  const ImageShare share{comm.rank(), comm.size()};
  const std::vector<PosedImage> train = LoadImages(scene, o.workspace, Split::kTrain, {}, share);
  const std::vector<PosedImage> test = LoadImages(scene, o.workspace, Split::kTest, {}, share);
  const int64_t test_views = static_cast<int64_t>(SplitViews(scene, Split::kTest).size());
  // A fresh start: an earlier run's checkpoints would be mistaken for this one's. They stay aside
  // until this run has a level of its own, and come back if it fails before.
  std::optional<PreviousRun> previous;
  if (start.level == 0 && root) previous.emplace(o.workspace);
  std::optional<JsonLog> log;  // rank 0's
  if (root) log.emplace(o.workspace / "recon" / "log.jsonl", start.level > 0, "reconstruction log");
  const auto write_log = [&](const json& line) {
    if (log) log->Write(line);
  };
  if (start.level > 0) write_log({{"event", "resume"}, {"level", start.level}});
  // Rank 0's first held-out view (its share starts with the split's first image), else training view.
  const std::vector<PosedImage>& preview_views = test.empty() ? train : test;
  json excluded_views = json::array();
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kExcluded) excluded_views.push_back({{"name", im.name}, {"because", im.excluded_because}});
  }
  say(StrCat("backend: ", result.backend, "; ", train_views.size(), " training and ", test_views, " held-out views",
             excluded_views.empty() ? std::string()
                                    : StrCat(" (", excluded_views.size(), " left out on import: scene.json says why)"),
             "; ", levels, " levels from ", o.start_resolution, "^3"));
  const TrainingViews views = ViewsForHierarchy(train, &comm, train_views);
  say(result.levels_choice.Describe());
  if (ho.exposures > 0) {
    say(StrCat("exposures: a gain and an offset per channel for each of the ", ho.exposures,
               " training photos; held-out views take the blend of their two nearest training photos'"));
  }
  // As every level's RaySet will (every rank's photos: either all have alpha or the scene's do not).
  const bool fits_alpha = o.residuals.use_alpha && !comm.Any(!ImagesHaveAlpha(train));
  const float opacity_weight = OpacityResidualWeight(o.residuals, fits_alpha);
  const std::string opacity_residual = opacity_weight <= 0 ? "off" : (fits_alpha ? "alpha" : "auxiliary");
  say(StrCat("opacity residual (weight ", opacity_weight, "): ",
             opacity_residual == "alpha" ? "the box opacity fits the photos' alpha"
             : opacity_residual == "off" ? "off"
                                         : "the paper's auxiliary term (0 or 1)"));
  say(result.fixed_background
          ? StrCat("background: fixed at (", scene.background[0], ", ", scene.background[1], ", ", scene.background[2],
                   ")", o.background == BackgroundChoice::kAuto ? ", the colour every photo's alpha was composited over" : "")
          : std::string("background: learned (environment shells)"));

  if (start.level == 0 && o.init_shells_from_photos) MeanColour(train, comm, ho.init.shell_colour);

  double elapsed = 0;  // solver time so far (excludes held-out evaluation and previews)
  auto t_level = WallClock::now();
  double eval_seconds = 0;  // held-out evaluation and previews within the level
  LevelReport lr;
  double level_start_elapsed = 0, iter_time = 0;  // for the log's elapsed solver time
  int held_out_iteration = -1;  // the iteration whose held-out PSNR was logged last
  double held_out_psnr = 0;
  // The photos' exposures at the level's current parameters (none when it solves none), read from
  // the backend once for a callback's scoring and preview.
  const auto exposures_of = [&](const HierarchyLevel& h) {
    if (h.shape.exposures == 0) return PhotoExposures();
    const auto t0 = WallClock::now();
    std::vector<float> x(static_cast<size_t>(h.shape.ParamCount()));
    backend->Download(h.params, x);
    eval_seconds += SecondsSince(t0);
    return PhotoExposures(h.shape, x, train_views);
  };
  // The mean PSNR over every rank's held-out views (collective).
  const auto held_out = [&](VecId params, const PhotoExposures& exposures) {
    const auto t0 = WallClock::now();
    double sum[2] = {0, 0};  // PSNR, views
    for (const ViewScore& s : ScoreViews(backend.get(), params, test, o.min_box_opacity, exposures)) {
      sum[0] += s.psnr;
      sum[1] += 1;
    }
    comm.SumInPlace(sum);
    eval_seconds += SecondsSince(t0);
    return sum[1] > 0 ? sum[0] / sum[1] : 0.0;
  };
  int64_t summed_at_level = 0, summed_at_iteration = 0;  // bytes summed across ranks so far
  double pass_at_level = 0, sum_at_level = 0;            // this rank's pass and sum seconds so far
  const auto summed_bytes = [&] { return ranks != nullptr ? ranks->bytes_summed() : int64_t{0}; };
  HierarchyCallbacks cb;
  cb.level_started = [&](const HierarchyLevel& h) {
    lr = LevelReport{};
    lr.level = h.level;
    lr.shape = h.shape;
    lr.image_downscale = h.image_downscale;
    lr.rays = comm.size() > 1 ? comm.ShareOf(h.rays).total : h.rays;  // every rank's
    held_out_iteration = -1;
    level_start_elapsed = elapsed + SecondsSince(t_level);  // setup (rays, SetLevel) counts
    iter_time = 0;
    summed_at_level = summed_at_iteration = summed_bytes();
    if (ranks != nullptr) {
      pass_at_level = ranks->pass_seconds();
      sum_at_level = ranks->sum_seconds();
    }
    const MemoryEstimate& mem = h.memory;
    say(StrCat("level ", h.level + 1, "/", levels, ": ", DescribeShape(h.shape), ", ", lr.rays, " rays",
               lr.image_downscale > 1 ? StrCat(" (images / ", lr.image_downscale, ")") : std::string(),
               comm.size() > 1 ? "; memory per rank: vectors " : "; memory: vectors ", FormatByteCount(mem.vectors),
               ", per-thread sums ", FormatByteCount(mem.scratch),
               ", Jacobian cache ",
               backend->CachesJacobian() ? FormatByteCount(mem.jacobian_cache) : std::string("off (recomputing)"),
               mem.available > 0 ? StrCat(" of ", FormatByteCount(mem.available), " available") : std::string()));
  };
  cb.iteration = [&](const HierarchyLevel& h, const IterationSummary& s) {
    iter_time += s.seconds_total;
    json line = IterationJson(lr, h.solver, s, level_start_elapsed + iter_time);
    if (ranks != nullptr) {
      line["ranks"] = comm.size();
      line["summed_bytes"] = summed_bytes() - summed_at_iteration;
      summed_at_iteration = summed_bytes();
    }
    const bool last_it = s.iteration + 1 == h.solver.max_iterations;
    const bool score = test_views > 0 && o.eval_every > 0 && ((s.iteration + 1) % o.eval_every == 0 || last_it);
    const bool preview = root && o.preview_every > 0 && ((s.iteration + 1) % o.preview_every == 0 || last_it);
    const PhotoExposures exposures = score || preview ? exposures_of(h) : PhotoExposures();
    if (score) {
      held_out_psnr = held_out(h.params, exposures);
      held_out_iteration = s.iteration;
      line["test_psnr"] = held_out_psnr;
    }
    if (preview) {
      const auto t0 = WallClock::now();
      const RenderOutput r = RenderAsShot(backend.get(), h.params, preview_views.front(), o.min_box_opacity, exposures);
      const fs::path p = o.workspace / "preview" / StrCat("recon_l", h.level, "_i", s.iteration + 1, ".png");
      EnsureWritableDirectory(p.parent_path());
      WriteImage(p, ToImage(r), PixelFormat::kUInt8);
      eval_seconds += SecondsSince(t0);
    }
    write_log(line);
    ReconstructOptions::Event e;
    e.level = h.level;
    e.levels = levels;
    e.iteration = s.iteration + 1;
    e.iterations = h.solver.max_iterations;
    e.cost = s.cost_after;
    e.train_psnr = s.train_psnr;
    emit(e);
    return true;
  };
  json photo_fits = nullptr;  // after the first level (photo_fit.h)
  std::vector<std::string> train_names;  // every rank's training photos, scene.json order
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kTrain) train_names.push_back(im.name);
  }
  json box_faces = json::array();  // after the first level (box_check.h)
  std::string box_warning;
  std::vector<int> grow_faces;  // set after level 0: fit it again in a box grown there
  json box_growths = json::array();
  cb.level_done = [&](const HierarchyLevel& h, const SolverSummary& summary, const std::vector<float>& x) {
    if (ranks != nullptr) ranks->CheckInStep(h.params);
    if (h.level == 0) {
      const std::vector<BoxFace> faces = BoxFaces(h.shape, geometry, x);
      box_faces = json::array();  // the last fit's (level 0 is fitted again after a growth)
      for (const BoxFace& f : faces) box_faces.push_back({{"face", f.name}, {"opaque_fraction", f.opaque_fraction}});
      box_warning = CutOffWarning(faces);
      if (o.grow_box && box_growths.size() < static_cast<size_t>(kMaxBoxGrowths) &&
          !FogCanLookOpaque(o.init.box_opacity, geometry, h.shape.n)) {
        grow_faces = FacesToGrow(faces);
      }
      if (!box_warning.empty() && grow_faces.empty()) say("warning: " + box_warning);
    }
    if (!grow_faces.empty()) {  // this fit is discarded (before_level ends the hierarchy here)
      const double seconds = SecondsSince(t_level) - eval_seconds;
      elapsed += seconds;
      result.solve_seconds += seconds;
      t_level = WallClock::now();
      eval_seconds = 0;
      return;
    }
    lr.iterations = summary.iterations;
    lr.cost = summary.final_cost;
    lr.train_psnr = summary.per_iteration.empty() ? 0 : summary.per_iteration.back().train_psnr;
    lr.status = StatusName(summary.status);
    const PhotoExposures fitted(h.shape, x, train_views);  // none when the level solves none
    if (h.level == 0) {
      const auto t0 = WallClock::now();
      const PhotoFits fits = CheckPhotoFits(backend.get(), h.params, train, train_names, fitted, comm, o.photo_fit);
      eval_seconds += SecondsSince(t0);
      photo_fits = fits.ToJson(o.photo_fit);
      write_log({{"event", "photo_fits"}, {"photo_fits", photo_fits}});
      if (!fits.poor.empty()) say("warning: " + fits.Warning(o.photo_fit));
    }
    if (test_views > 0) {
      // The last iteration's, when the log has it; else now (the backend still holds x).
      lr.test_psnr = held_out_iteration == summary.iterations - 1 ? held_out_psnr : held_out(h.params, fitted);
    }
    if (!fitted.empty()) {
      result.gain_range[0] = 2, result.gain_range[1] = 0;
      for (const ColourTransform<float>& xf : fitted.transforms()) {
        for (float g : xf.gain) {
          result.gain_range[0] = std::min(result.gain_range[0], g);
          result.gain_range[1] = std::max(result.gain_range[1], g);
        }
      }
    }
    if (root) {
      WriteCheckpoint(CheckpointPath(o.workspace, h.level),
                      MakeCheckpoint(scene, h.level, h.shape, summary.iterations, o.solver.type, x));
    }
    if (previous) previous->Discard();
    lr.seconds = SecondsSince(t_level) - eval_seconds;
    elapsed += lr.seconds;
    json level_line{{"event", "level"},
                    {"level", h.level},
                    {"n", h.shape.n},
                    {"iterations", lr.iterations},
                    {"seconds", lr.seconds},
                    {"elapsed", elapsed},
                    {"cost", lr.cost},
                    {"train_psnr", lr.train_psnr},
                    {"test_psnr", lr.test_psnr},
                    {"status", lr.status},
                    {"smoothness_weights",
                     {{"grid_colour", summary.smoothness.grid_colour},
                      {"grid_density", summary.smoothness.grid_density},
                      {"shell_colour", summary.smoothness.shell_colour},
                      {"shell_opacity", summary.smoothness.shell_opacity}}},
                    {"report", summary.BriefReport()}};
    if (ranks != nullptr) {
      // Every rank's seconds in its own passes and in the sums (waiting for the slowest included).
      const size_t n = static_cast<size_t>(comm.size()), me = static_cast<size_t>(comm.rank());
      std::vector<double> seconds(2 * n, 0.0);
      seconds[me] = ranks->pass_seconds() - pass_at_level;
      seconds[n + me] = ranks->sum_seconds() - sum_at_level;
      comm.SumInPlace(seconds);
      level_line["rank_pass_seconds"] = std::vector<double>(seconds.begin(), seconds.begin() + static_cast<ptrdiff_t>(n));
      level_line["rank_sum_seconds"] = std::vector<double>(seconds.begin() + static_cast<ptrdiff_t>(n), seconds.end());
      level_line["ranks"] = comm.size();
      level_line["summed_bytes"] = summed_bytes() - summed_at_level;
      level_line["summed_bytes_per_iteration"] =
          summary.iterations > 0 ? (summed_bytes() - summed_at_level) / summary.iterations : 0;
    }
    write_log(level_line);
    say(StrCat("level ", h.level + 1, "/", levels, " done in ", lr.seconds, " s: ", summary.BriefReport(),
               test_views == 0 ? std::string() : StrCat("; held-out PSNR ", lr.test_psnr, " dB")));
    result.levels.push_back(lr);
    result.solve_seconds += lr.seconds;
    result.final_checkpoint = CheckpointPath(o.workspace, h.level);
    result.test_psnr = lr.test_psnr;
    t_level = WallClock::now();
    eval_seconds = 0;
  };
  cb.before_level = [&](int) { return grow_faces.empty(); };
  cb.out_of_memory = [&](const HierarchyLevel& h) {
    result.memory_stop = StrCat("level ", h.level + 1, " (", DescribeShape(h.shape), ") would need ",
                                FormatByteCount(h.memory.Needed()), " but ",
                                FormatByteCount(h.memory.available), " are available");
    say(StrCat(result.memory_stop, ": the reconstruction ends at level ", h.level, " (--levels ", h.level,
               " next time, or a smaller --max-size)"));
    if (result.final_checkpoint.empty()) {  // a resumed run whose first level did not fit
      result.final_checkpoint = CheckpointPath(o.workspace, h.level - 1);
      result.already_complete = true;
    }
  };
  for (;;) {
    SolveHierarchy(backend.get(), geometry, views, ho, std::move(start), cb);
    if (grow_faces.empty()) break;
    // The object goes on beyond these faces: grow the box there (every rank alike, from the same
    // fit), write it to scene.json, and fit level 0 again.
    std::string names, described;
    for (int f : grow_faces) {
      const std::string name = box_faces[f]["face"].get<std::string>();
      names += StrCat(names.empty() ? "" : ", ", name);
      described += StrCat(described.empty() ? "" : ", ", name, " (",
                          std::lround(100 * box_faces[f]["opaque_fraction"].get<double>()), " % opaque)");
    }
    const VolumePlacement grown = GrownPlacement(VolumePlacement::FromScene(scene), grow_faces);
    for (int a = 0; a < 3; ++a) {
      scene.box.center[a] = grown.box_center[a];
      scene.box.size[a] = grown.box_size[a];
    }
    scene.box.method += StrCat("; grown by perf reconstruct at ", names);
    geometry = VolumeGeometry::From(grown, scene_path.string());
    if (root) WriteScene(scene_path, scene);
    const json growth{{"faces", names}, {"size", {grown.box_size[0], grown.box_size[1], grown.box_size[2]}},
                      {"center", {grown.box_center[0], grown.box_center[1], grown.box_center[2]}}};
    box_growths.push_back(growth);
    write_log({{"event", "box_grown"}, {"growth", growth}});
    say(StrCat("the fitted density reaches the box's ", described, grow_faces.size() > 1 ? " faces" : " face",
               ": the object goes on there; the box grows ", std::lround(100 * kGrowFraction), " % there, to ",
               grown.box_size[0], " x ", grown.box_size[1], " x ", grown.box_size[2],
               " (scene.json), and level 1 is fitted again"));
    grow_faces.clear();
    start = HierarchyStart{};
  }
  if (result.already_complete || !root) return result;

  json levels_json = json::array();
  for (const LevelReport& l : result.levels) {
    levels_json.push_back({{"level", l.level},
                           {"n", l.shape.n},
                           {"m", l.shape.m},
                           {"bricks", l.shape.StoredBricks()},
                           {"image_downscale", l.image_downscale},
                           {"rays", l.rays},
                           {"iterations", l.iterations},
                           {"seconds", l.seconds},
                           {"cost", l.cost},
                           {"train_psnr", l.train_psnr},
                           {"test_psnr", l.test_psnr},
                           {"status", l.status},
                           {"checkpoint", fs::relative(CheckpointPath(o.workspace, l.level), o.workspace).string()}});
  }
  const json summary{{"format", "perf-recon"},
                     {"version", 1},
                     {"backend", result.backend},
                     {"ranks", result.ranks},
                     {"solver", SolverName(o.solver.type)},
                     {"smooth_grid", ho.solver.smooth_grid},
                     {"smooth_shells", ho.solver.smooth_shells},
                     {"background", result.fixed_background ? "fixed" : "learned"},
                     {"sh_degree", o.sh_degree},
                     {"exposures",
                      {{"photos", result.exposures},
                       {"prior", ho.solver.exposure_prior},
                       {"gain_range", {result.gain_range[0], result.gain_range[1]}},
                       {"held_out", result.exposures > 0 ? "the inverse-distance blend of the two nearest training photos' (camera centres)" : "none"}}},
                     {"robust_scale", o.residuals.robust_scale},
                     {"robust_from_level", ho.robust_from_level + 1},
                     {"opacity_residual", opacity_residual},
                     {"opacity_residual_weight", opacity_weight},
                     {"init_opacity", o.init.box_opacity},
                     {"min_box_opacity", o.min_box_opacity},  // the render rule of test_psnr
                     {"levels", levels},
                     {"start_resolution", o.start_resolution},
                     {"pixels_across_box", result.levels_choice.pixels_across_box},
                     {"levels_chosen", result.levels_choice.automatic ? "from the photos" : "as given"},
                     {"max_resolution", result.levels_choice.max_resolution},
                     {"levels_note", result.levels_choice.Describe()},
                     {"memory_stop", result.memory_stop},
                     {"iterations_per_level", o.iterations},
                     {"level_iterations", o.level_iterations},
                     {"excluded_views", excluded_views},
                     {"photo_fits", photo_fits},
                     {"box_faces", box_faces},
                     {"box_warning", box_warning},
                     {"box_growths", box_growths},
                     {"final_checkpoint", fs::relative(result.final_checkpoint, o.workspace).string()},
                     {"test_psnr", result.test_psnr},
                     {"solve_seconds", result.solve_seconds},
                     {"levels_run", levels_json}};
  WriteFileAtomically(o.workspace / "recon" / "recon.json", summary.dump(2) + "\n");
  return result;
}

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
