#include "sfm_import/colmap_runner.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <system_error>
#include <vector>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/inputs.h"
#include "common/owned_files.h"
#include "sfm_import/camera_groups.h"
#include "sfm_import/capture_order.h"
#include "sfm_import/colmap_process.h"
#include "sfm_import/sfm_inputs.h"
#include "sfm_import/sfm_matching_time.h"
#include "sfm_import/sfm_models.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

using namespace sfm_detail;
using Clock = std::chrono::steady_clock;

// The photos' header tags, one per input photo (ReadPhotoTags).
using PhotoTags = std::vector<std::optional<CameraTags>>;

constexpr const char* kTooFewHint =
    "photos need more overlap (each point seen in 3+ photos, neighbours sharing 60-80% of the "
    "view), more texture, or more photos; if they were not taken in order, try --matcher "
    "exhaustive";

// "71, 8 and 3", largest first.
std::string ModelSizes(std::vector<int> sizes) {
  std::sort(sizes.rbegin(), sizes.rend());
  std::string out;
  for (size_t i = 0; i < sizes.size(); ++i) out += StrCat(i == 0 ? "" : i + 1 == sizes.size() ? " and " : ", ", sizes[i]);
  return out;
}

// What every step of one run shares: the options, the photos, COLMAP, its files and its log.
struct SfmRun {
  SfmRun(const SfmOptions& o, const std::vector<std::string>& photos)
      : options(o), inputs(photos), n(static_cast<int>(photos.size())) {}

  // Runs one COLMAP step with this run's log and progress.
  StepResult Step(const std::vector<std::string>& args, const std::string& stage, const ProgressParser& parse) {
    return steps.Run(args, stage, parse);
  }
  const fs::path& log_path() const { return steps.log_path(); }

  const SfmOptions& options;
  const std::vector<std::string>& inputs;  // the photos, as COLMAP names them
  int n = 0;                                // how many
  fs::path colmap_dir;                      // WORKSPACE/colmap
  fs::path database, models_dir;            // in colmap_dir
  ColmapSteps steps;                        // the binary and colmap_dir/colmap.log
  std::string threads;  // every step's number of threads
  int exhaustive_max = 0;  // the most photos auto mode matches pair by pair (AutoExhaustiveMax)
  double match_seconds = 0, map_seconds = 0;  // the last Match's and Map's
};

// The models of one mapper run. COLMAP writes one numbered folder per disconnected model; the
// one with the most images is the scene, the others are fragments it could not attach.
struct Mapping {
  std::optional<fs::path> best_dir;  // the model with the most images (then points), if any
  ModelCounts best;
  std::vector<int> model_sizes;   // photos in each model COLMAP made
  bool no_initial_pair = false;  // COLMAP found no pair of photos to start from
};

// A matcher's arguments with the SIFT matching settings every matching step shares.
std::vector<std::string> WithSiftMatching(const SfmRun& run, std::vector<std::string> args) {
  args.insert(args.end(), {"--SiftMatching.use_gpu", "0", "--SiftMatching.num_threads", run.threads});
  return args;
}

// A mapping step's arguments with the settings every one shares: threads and how sure a placement must be.
std::vector<std::string> WithMapper(const SfmRun& run, std::vector<std::string> args) {
  args.insert(args.end(), {"--Mapper.num_threads", run.threads, "--Mapper.abs_pose_min_num_inliers",
                           std::to_string(run.options.MinPoseInliers()), "--Mapper.abs_pose_min_inlier_ratio",
                           StrCat(run.options.min_pose_inlier_ratio)});
  return args;
}

// Without --force, a model already at WORKSPACE/sparse/0 is kept: says so and fills `result`'s
// counts from it. False when there is none, when it was made from other photos than `inputs`
// (said), or with --force.
bool KeepExistingModel(const SfmOptions& options, const std::vector<std::string>& inputs, SfmResult* result) {
  if (options.force) return false;
  const auto counts = ReadModelCounts(result->sparse_dir);
  if (!counts) return false;
  if (const std::string why = InputsChanged(options, inputs); !why.empty()) {
    Report(options, StrCat("sfm: ", result->sparse_dir.string(), " was ", why, ": running COLMAP again"));
    return false;
  }
  Report(options, StrCat("sfm: skipped, ", result->sparse_dir.string(), " already exists (",
                         counts->num_images, " images, ", counts->num_points,
                         " points); use --force to run COLMAP again"));
  result->num_registered_images = counts->num_images;
  result->num_points = counts->num_points;
  result->kept = true;
  return true;
}

// Finds colmap, clears WORKSPACE/colmap of an earlier run's database and models, and opens the
// log (appended to).
SfmRun StartRun(const SfmOptions& options, const std::vector<std::string>& inputs) {
  SfmRun run(options, inputs);
  const fs::path colmap = FindColmap(options.colmap_binary);
  run.colmap_dir = options.workspace / "colmap";
  EnsureWorkFolder(run.colmap_dir);  // COLMAP's: PERF removes its database and models between runs
  run.database = run.colmap_dir / "database.db";
  run.models_dir = run.colmap_dir / "sparse";

  // Start from scratch: COLMAP silently keeps the cameras and features already in a database
  // (so a changed --camera-model or --max-image-size would not take effect), and model folders
  // from an earlier run would compete with the new ones.
  for (const char* suffix : {"", "-shm", "-wal"}) RemoveOwned(run.database.string() + suffix);
  RemoveOwned(run.models_dir);
  EnsureWritableDirectory(run.models_dir);
  run.steps = ColmapSteps(options, colmap, run.colmap_dir / "colmap.log");
  run.threads = std::to_string(options.num_threads);
  run.exhaustive_max = AutoExhaustiveMax(options);
  return run;
}

// Beyond the exhaustive limit, auto mode lets the photos' capture times choose the matcher.
bool OrderMatters(const SfmRun& run) {
  return run.options.matcher == "auto" && run.n > run.exhaustive_max;
}

// The photos' headers, read once: for the camera groups (ExtractFeatures), and beyond the
// exhaustive limit for the capture order (ChooseExhaustive); empty when neither needs them.
PhotoTags ReadTagsIfNeeded(const SfmRun& run) {
  PhotoTags tags;
  if (run.options.single_camera || OrderMatters(run)) tags = ReadPhotoTags(run.options.images, run.inputs);
  return tags;
}

// (a) Features. CPU SIFT: this build of COLMAP has no CUDA, and GPU SIFT would need an
// OpenGL context that a headless machine lacks.
// With a shared camera, one per group of photos that agree on size and EXIF camera
// (camera_groups.h): each group's extraction run (its own image list) adds one camera.
void ExtractFeatures(SfmRun& run, const PhotoTags& tags) {
  const SfmOptions& options = run.options;
  std::vector<CameraGroup> groups;
  if (options.single_camera) {
    groups = GroupByCamera(run.inputs, tags);
    Report(options, "sfm: " + DescribeGroups(groups));
  }
  Report(options, StrCat("sfm: extracting features from ", run.n, " images (", run.steps.colmap().string(), ")"));
  const auto extract = [&](const std::vector<std::string>& list_args) {
    std::vector<std::string> args = {"feature_extractor", "--database_path", run.database.string(), "--image_path",
                                     options.images.string(), "--ImageReader.camera_model", options.camera_model,
                                     "--ImageReader.single_camera", options.single_camera ? "1" : "0",
                                     "--SiftExtraction.use_gpu", "0", "--SiftExtraction.max_image_size",
                                     std::to_string(options.max_image_size), "--SiftExtraction.max_num_features",
                                     std::to_string(options.max_num_features), "--SiftExtraction.num_threads", run.threads};
    if (!options.camera_params.empty()) args.insert(args.end(), {"--ImageReader.camera_params", options.camera_params});
    args.insert(args.end(), list_args.begin(), list_args.end());
    const StepResult r = run.Step(args, "features", ExtractionParser());
    if (r.failed()) ThrowStepFailed("feature_extractor", r, run.log_path());
  };
  if (groups.size() > 1) {
    for (size_t g = 0; g < groups.size(); ++g) {
      const fs::path list = run.colmap_dir / StrCat("camera_", g + 1, "_images.txt");
      std::string text;
      for (const std::string& name : groups[g].names) text += name + "\n";
      WriteFileAtomically(list, text);
      extract({"--image_list_path", list.string()});
    }
  } else {
    extract({});
  }
}

// (b) Matching. Exhaustive is quadratic in the number of images but robust to any capture
// order; sequential assumes photos were taken in order (a walk around the object).
// True for exhaustive.
bool ChooseExhaustive(const SfmRun& run, const PhotoTags& tags) {
  const SfmOptions& options = run.options;
  bool exhaustive = options.matcher == "exhaustive" || (options.matcher == "auto" && run.n <= run.exhaustive_max);
  if (OrderMatters(run)) {
    if (run.n <= options.exhaustive_max_images) {  // within --exhaustive-max: the budget chose
      Report(options, StrCat("sfm: every pair of the ", run.n, " photos would take about ",
                             static_cast<int>(PairSeconds(options) * run.n * (run.n - 1) / 2),
                             " s, more than half of what the time budget leaves: matching in sequence"));
    }
    // Beyond the exhaustive limit: do the photos' capture times say the names are in order?
    const CaptureOrder order = OrderFromTags(tags);
    Report(options, "sfm: " + order.Describe());
    exhaustive = order.Known() && !order.NamesFollowTime();
  }
  return exhaustive;
}

// Runs the matcher chosen (ChooseExhaustive) over the features in the database.
void Match(SfmRun& run, bool exhaustive) {
  const SfmOptions& options = run.options;
  std::vector<std::string> args;
  ProgressParser parser;
  if (exhaustive) {
    Report(options, StrCat("sfm: matching all ", run.n * (run.n - 1) / 2, " pairs (exhaustive)"));
    args = {"exhaustive_matcher", "--database_path", run.database.string()};
    parser = ExhaustiveParser();
  } else {
    Report(options, StrCat("sfm: matching each image with its ", options.sequential_overlap,
                           " neighbours (sequential)"));
    args = {"sequential_matcher",
            "--database_path",
            run.database.string(),
            "--SequentialMatching.overlap",
            std::to_string(options.sequential_overlap),
            "--SequentialMatching.quadratic_overlap",
            "1"};
    parser = SequentialParser();
  }
  const Clock::time_point start = Clock::now();
  const StepResult r = run.Step(WithSiftMatching(run, args), "matching", parser);
  run.match_seconds = std::chrono::duration<double>(Clock::now() - start).count();
  if (r.failed()) {
    ThrowStepFailed(exhaustive ? "exhaustive_matcher" : "sequential_matcher", r, run.log_path());
  }
}

// (c) Incremental mapping into a fresh colmap/sparse; reads the sizes of the models it made.
Mapping Map(SfmRun& run) {
  Report(run.options, "sfm: mapping (incremental reconstruction)");
  RemoveOwned(run.models_dir);
  EnsureWritableDirectory(run.models_dir);
  Mapping m;
  const Clock::time_point start = Clock::now();
  const StepResult r = run.Step(
      WithMapper(run, {"mapper", "--database_path", run.database.string(), "--image_path", run.options.images.string(),
                       "--output_path", run.models_dir.string()}),
      "mapping", MapperParser(run.n));
  run.map_seconds = std::chrono::duration<double>(Clock::now() - start).count();
  // COLMAP 3.8 exits with 1 when no initial pair could be found: a property of the photos,
  // not a failure of the tool.
  m.no_initial_pair = !r.idle && !r.signal && r.exit_code != 0 && r.saw("failed to create sparse model");
  if (r.failed() && !m.no_initial_pair) ThrowStepFailed("mapper", r, run.log_path());
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(run.models_dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (!entry.is_directory() || name.empty() || name.find_first_not_of("0123456789") != std::string::npos) continue;
    const auto counts = ReadModelCounts(entry.path());
    if (!counts) continue;
    m.model_sizes.push_back(counts->num_images);
    if (!m.best_dir || counts->num_images > m.best.num_images ||
        (counts->num_images == m.best.num_images && counts->num_points > m.best.num_points)) {
      m.best_dir = entry.path();
      m.best = *counts;
    }
  }
  return m;
}

// Matches the pairs not matched yet (COLMAP keeps those that are).
void MatchEveryPair(SfmRun& run) {
  const StepResult r = run.Step(WithSiftMatching(run, {"exhaustive_matcher", "--database_path", run.database.string()}),
                                "matching", ExhaustiveParser());
  if (r.failed()) ThrowStepFailed("exhaustive_matcher", r, run.log_path());
}

// Sequential matching assumed the photos were taken in order (file names give no other clue
// when EXIF is stripped). A model of fewer than half of them says they were not: match the
// remaining pairs (COLMAP keeps the pairs already matched) and map again.
void RematchIfOutOfOrder(SfmRun& run, bool* exhaustive, Mapping* mapping) {
  if (*exhaustive || run.options.matcher != "auto" || mapping->best.num_images >= run.n / 2) return;
  Report(run.options, StrCat("sfm: sequential matching put only ", mapping->best.num_images, " of ", run.n,
                             " photos in a model, so they were not taken in order: matching every pair and mapping again"));
  MatchEveryPair(run);
  *exhaustive = true;
  *mapping = Map(run);
}

// Throws InputError when the largest model holds too few photos, or there is none.
void CheckEnoughRegistered(const SfmRun& run, const Mapping& mapping) {
  const SfmOptions& options = run.options;
  if (!mapping.best_dir && mapping.no_initial_pair) {
    throw InputError(options.images.string(), "registered images", StrCat("0 of ", run.n),
                     "COLMAP could not reconstruct any part of the scene (no pair of photos "
                     "with enough matches; see " + run.log_path().string() + ")",
                     kTooFewHint);
  }
  if (!mapping.best_dir || mapping.best.num_images < options.min_registered_images) {
    throw InputError(
        options.images.string(), "registered images", StrCat(mapping.best.num_images, " of ", run.n),
        StrCat("too few images registered (at least ", options.min_registered_images,
               " needed; largest of ", mapping.model_sizes.size(), " models in ", run.models_dir.string(), ")"),
        kTooFewHint);
  }
}

// Writes colmap/second_pass_pairs.txt: each photo in `missing` with every other photo, each
// pair once. `num_pairs` gets their count.
fs::path WriteSecondPassPairs(const SfmRun& run, const std::vector<std::string>& missing, int64_t* num_pairs) {
  const fs::path pairs = run.colmap_dir / "second_pass_pairs.txt";
  std::string text;
  const std::set<std::string> missing_set(missing.begin(), missing.end());
  for (const std::string& a : missing) {
    for (const std::string& b : run.inputs) {
      if (a == b || (missing_set.count(b) && b < a)) continue;  // each pair once
      text += a + " " + b + "\n";
      ++*num_pairs;
    }
  }
  WriteFileAtomically(pairs, text);
  return pairs;
}

// A registration pass's model in `dir` replaces the best where it holds more photos: says how
// many the pass added and records it in `passes`. False where it added none.
bool Adopt(const SfmRun& run, const fs::path& dir, bool ok, int pass, Mapping* mapping, std::vector<int>* passes) {
  const std::optional<ModelCounts> counts = ok ? ReadModelCounts(dir) : std::nullopt;
  const int added = counts ? std::max(0, counts->num_images - mapping->best.num_images) : 0;
  Report(run.options, StrCat("sfm: pass ", pass, " registered ", added, " more (", mapping->best.num_images + added, "/", run.n, ")"));
  if (added == 0) return false;
  passes->push_back(added);
  *std::max_element(mapping->model_sizes.begin(), mapping->model_sizes.end()) = counts->num_images;  // it grew
  mapping->best_dir = dir;
  mapping->best = *counts;
  return true;
}

// (d) Sequential matching misses photos taken out of order: match those left out with every
// other photo and register them into the model (COLMAP's image_registrator), then adjust. Photos
// that see too few of the model's points then are tried again as the model grows: each further
// pass triangulates the points the photos registered so far see (point_triangulator) and
// registers again, until a pass adds none; then the model is adjusted once more (COLMAP's mapper
// continued from the model added 5 photos in one run and none in the next on the same photos;
// these passes add the same every time: docs/tuning.md). A pass's model replaces the best only
// when every step worked and it holds more photos; `passes` gets the photos each pass added.
void RegisterLeftOut(SfmRun& run, bool exhaustive, Mapping* mapping, std::vector<int>* passes) {
  if (exhaustive || !run.options.second_pass || mapping->best.num_images >= run.n) return;
  const auto missing = LeftOut(run.inputs, *mapping->best_dir);
  if (!missing || missing->empty()) return;
  int64_t num_pairs = 0;
  const fs::path pairs = WriteSecondPassPairs(run, *missing, &num_pairs);
  Report(run.options, StrCat("sfm: ", mapping->best.num_images, "/", run.n, " images registered after sequential matching; matching the ",
                             missing->size(), " left out with every other photo (", num_pairs, " pairs)"));
  bool ok = true;
  const auto step = [&](const std::vector<std::string>& args, const std::string& stage, const ProgressParser& parse) {
    if (!ok) return;
    ok = !run.Step(args, stage, parse).failed();
    if (!ok) Report(run.options, StrCat("sfm: ", args.front(), " failed (see ", run.log_path().string(), "); keeping the model before it"));
  };
  const ProgressParser quiet = [](const std::string&) { return std::optional<std::string>(); };
  const auto model_dir = [&](const std::string& name) {
    const fs::path dir = run.models_dir / name;
    RemoveOwned(dir);
    EnsureWritableDirectory(dir);
    return dir;
  };
  const fs::path second = model_dir("second_pass");
  step(WithSiftMatching(run, {"matches_importer", "--database_path", run.database.string(), "--match_list_path",
                              pairs.string(), "--match_type", "pairs"}),
       "matching", ExhaustiveParser());
  step(WithMapper(run, {"image_registrator", "--database_path", run.database.string(), "--input_path",
                        mapping->best_dir->string(), "--output_path", second.string()}),
       "registering", MapperParser(run.n));
  step({"bundle_adjuster", "--input_path", second.string(), "--output_path", second.string()}, "adjusting", quiet);
  if (!Adopt(run, second, ok, 2, mapping, passes)) return;
  for (int pass = 3; mapping->best.num_images < run.n && pass < 3 + run.options.max_more_passes; ++pass) {
    const fs::path points = model_dir(StrCat("pass_", pass, "_points")), next = model_dir(StrCat("pass_", pass));
    step(WithMapper(run, {"point_triangulator", "--database_path", run.database.string(), "--image_path",
                          run.options.images.string(), "--input_path", mapping->best_dir->string(), "--output_path",
                          points.string()}),
         "triangulating", quiet);
    step(WithMapper(run, {"image_registrator", "--database_path", run.database.string(), "--input_path",
                          points.string(), "--output_path", next.string()}),
         "registering", MapperParser(run.n));
    if (!Adopt(run, next, ok, pass, mapping, passes)) break;
  }
  if (passes->size() > 1) {  // the photos the later passes added, adjusted with the rest
    step({"bundle_adjuster", "--input_path", mapping->best_dir->string(), "--output_path", mapping->best_dir->string()},
         "adjusting", quiet);
  }
}

// (e) A model that looks wrong (options.check_model) after sequential matching is made again from
// every pair, and kept where it does not look wrong, else the first (set aside in
// colmap/first_model while the mapper runs again); under a time budget that cannot afford it too,
// saying so. `doubt` gets the kept one's.
void RemakeIfWrong(SfmRun& run, bool* exhaustive, Mapping* mapping, std::string* doubt) {
  if (!run.options.check_model) return;
  *doubt = run.options.check_model(*mapping->best_dir);
  if (doubt->empty() || *exhaustive || run.options.matcher != "auto") return;
  Report(run.options, StrCat("sfm: the model of ", mapping->best.num_images, " photos looks wrong (", *doubt,
                             "): matching every pair and mapping again"));
  if (run.options.seconds_left) {
    const double needs = EveryPairSeconds(run.options, run.n, run.match_seconds, run.map_seconds), left = run.options.seconds_left();
    if (needs > left) {
      Report(run.options, StrCat("sfm: matching every pair and mapping again will take about ", static_cast<int>(needs),
                                 " s, more than the time budget leaves (", static_cast<int>(std::max(0.0, left)),
                                 " s): the run passes its budget rather than fit a model that looks wrong"));
    }
  }
  const fs::path first = run.colmap_dir / "first_model";
  ReplaceDirectory(*mapping->best_dir, first);
  Mapping before = *mapping;
  before.best_dir = first;
  MatchEveryPair(run);
  *exhaustive = true;
  Mapping again = Map(run);
  const std::string again_doubt = again.best_dir ? run.options.check_model(*again.best_dir) : "no model";
  if (again.best_dir && again_doubt.empty() && again.best.num_images >= run.options.min_registered_images) {
    Report(run.options, StrCat("sfm: the model from every pair (", again.best.num_images, " photos) looks right: it is kept"));
    *mapping = again;
    doubt->clear();
    return;
  }
  Report(run.options, StrCat("sfm: the model from every pair looks wrong too (", again_doubt, "): keeping the first"));
  *mapping = before;
}

// The chosen model becomes WORKSPACE/sparse/0; `result` gets its counts and the photos it left out.
void InstallModel(const SfmRun& run, const Mapping& mapping, SfmResult* result) {
  ReplaceDirectory(*mapping.best_dir, result->sparse_dir);
  WriteInputsRecord(run.options, run.inputs);
  result->num_registered_images = mapping.best.num_images;
  result->num_points = mapping.best.num_points;
  if (const auto missing = LeftOut(run.inputs, result->sparse_dir)) result->left_out = *missing;
}

// The closing lines: what the model holds, the photos it left out, and what to try when it
// left out many.
void ReportModel(const SfmRun& run, const Mapping& mapping, bool exhaustive, const SfmResult& result) {
  const ModelCounts& best = mapping.best;
  const std::vector<int>& model_sizes = mapping.model_sizes;
  const int n = run.n;
  Report(
      run.options,
      StrCat("sfm: ", best.num_images, "/", n, " images registered, ", best.num_points, " points",
             model_sizes.size() > 1 ? StrCat(" (the largest of ", model_sizes.size(), " models of ", ModelSizes(model_sizes), " photos)")
                                    : "",
             ", in ",
             static_cast<int>(result.seconds + 0.5), " s -> ", result.sparse_dir.string()));
  if (!result.left_out.empty()) Report(run.options, "sfm: left out: " + NameList(result.left_out));
  if (!result.doubt.empty()) {
    Report(run.options, "sfm: warning: the model looks wrong (" + result.doubt +
                            "); perf import checks it again and names what it finds");
  }
  if (best.num_images < 0.9 * n) {
    Report(run.options, StrCat("sfm: warning: only ", best.num_images, " of ", n, " photos (",
                               static_cast<int>(100.0 * best.num_images / n), " %) are in the model; ",
                               exhaustive ? "try more features (--max-features) or larger images (--max-image-size)"
                                          : "try --matcher exhaustive (slower, order-free)",
                               ", or add photos that overlap those left out"));
  }
}

}  // namespace

SfmResult RunSfm(const SfmOptions& options) {
  options.Check();
  const Clock::time_point start = Clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };

  SfmResult result;
  const std::vector<std::string> inputs = ListInputImages(options.images);
  result.num_input_images = static_cast<int>(inputs.size());
  result.sparse_dir = options.workspace / "sparse" / "0";
  if (KeepExistingModel(options, inputs, &result)) {
    result.seconds = elapsed();
    return result;
  }

  CheckPhotosReadable(options.images, inputs);
  SfmRun run = StartRun(options, inputs);
  const PhotoTags tags = ReadTagsIfNeeded(run);
  ExtractFeatures(run, tags);
  bool exhaustive = ChooseExhaustive(run, tags);
  Match(run, exhaustive);
  Mapping mapping = Map(run);
  RematchIfOutOfOrder(run, &exhaustive, &mapping);
  CheckEnoughRegistered(run, mapping);
  RegisterLeftOut(run, exhaustive, &mapping, &result.passes);
  RemakeIfWrong(run, &exhaustive, &mapping, &result.doubt);
  result.exhaustive = exhaustive;
  InstallModel(run, mapping, &result);
  result.seconds = elapsed();
  ReportModel(run, mapping, exhaustive, result);
  return result;
}

}  // namespace perf
