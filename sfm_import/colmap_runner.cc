#include "sfm_import/colmap_runner.h"

#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <deque>
#include <fstream>
#include <optional>
#include <regex>
#include <set>
#include <system_error>
#include <vector>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/subprocess.h"
#include "sfm_import/camera_groups.h"
#include "sfm_import/capture_order.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_model.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

using Clock = std::chrono::steady_clock;

constexpr const char* kCommandLine = "command line";
constexpr size_t kLogTailLines = 15;

void Report(const SfmOptions& options, const std::string& line) {
  if (options.progress) options.progress(line);
}

// --------------------------------------------------------------------------------------------
// Input photos

// What COLMAP (through FreeImage) reads in practice. Counting by extension, not by decoding,
// keeps this cheap on large folders; COLMAP itself skips files it cannot decode.
bool LooksLikeImage(const fs::path& path) {
  static constexpr std::array<std::string_view, 11> kExtensions = {
      ".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".ppm", ".pgm", ".webp", ".jp2", ".exr"};
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return std::find(kExtensions.begin(), kExtensions.end(), ext) != kExtensions.end();
}

// The photos under `images` (recursively, as COLMAP's ImageReader does), as COLMAP names them:
// '/'-separated paths relative to `images`, sorted.
std::vector<std::string> ListInputImages(const fs::path& images) {
  std::error_code ec;
  if (!fs::exists(images, ec)) {
    throw InputError(kCommandLine, "--images", images.string(), "the images folder does not exist",
                     "pass the folder that holds your photos");
  }
  if (!fs::is_directory(images, ec)) {
    throw InputError(kCommandLine, "--images", images.string(), "not a folder",
                     "pass the folder that holds your photos, not a single file");
  }
  std::vector<std::string> names;
  fs::recursive_directory_iterator it(images, fs::directory_options::skip_permission_denied, ec);
  if (ec) {
    throw IoError(images.string(), "cannot list the images folder: " + ec.message(),
                  "check its permissions");
  }
  for (const fs::recursive_directory_iterator end; it != end; it.increment(ec)) {
    if (ec) {
      throw IoError(images.string(), "cannot list the images folder: " + ec.message(),
                    "check its permissions");
    }
    if (it->is_regular_file(ec) && LooksLikeImage(it->path())) {
      names.push_back(it->path().lexically_relative(images).generic_string());
    }
  }
  if (names.empty()) {
    throw InputError(kCommandLine, "--images", images.string(),
                     "the folder holds no images (looked for .jpg, .jpeg, .png, .tif, .tiff, .bmp, "
                     ".ppm, .pgm, .webp, .jp2, .exr, also in sub-folders)",
                     "put your photos in it or pass the folder that holds them");
  }
  std::sort(names.begin(), names.end());
  return names;
}

// --------------------------------------------------------------------------------------------
// Finding and running colmap

fs::path FindColmap(const std::string& binary) {
  return FindExecutable(binary,
                        "install COLMAP (`sudo apt-get install colmap`, or run scripts/setup.sh), or pass its path "
                        "with --colmap-binary");
}

// What a line of a step's output says about progress, as a short status, or nullopt.
using ProgressParser = std::function<std::optional<std::string>(const std::string& line)>;

struct StepResult {
  int exit_code = 0;             // valid when signal == 0
  int signal = 0;                // the signal that killed the process, or 0
  std::deque<std::string> tail;  // last output lines
  bool saw(const std::string& needle) const {
    return std::any_of(tail.begin(), tail.end(),
                       [&](const std::string& l) { return l.find(needle) != std::string::npos; });
  }
};

std::string Timestamp() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  ::localtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S", &tm);
  return buf;
}

// Runs `colmap <args>` without a shell (paths with spaces or quotes pass through untouched),
// headless, with stdout and stderr through one pipe: every byte is appended to `log` and every
// line is offered to `parse`, whose status is reported at most once a second.
StepResult RunColmapStep(const fs::path& colmap, const std::vector<std::string>& args,
                         const std::string& stage, const ProgressParser& parse,
                         const SfmOptions& options, std::ofstream& log, const fs::path& log_path) {
  const std::string command_line = CommandLine(colmap, args);
  // A prefix of our own: COLMAP's headings are lines of '=' already.
  log << "\n[perf " << Timestamp() << "] run: " << command_line << "\n" << std::flush;

  StepResult result;
  std::string partial;
  std::string pending_status;
  Clock::time_point last_report = Clock::now();
  auto handle_line = [&](std::string line) {
    if (line.empty()) return;
    if (auto status = parse ? parse(line) : std::nullopt) pending_status = *status;
    if (!pending_status.empty() && Clock::now() - last_report >= std::chrono::seconds(1)) {
      Report(options, stage + ": " + pending_status);
      pending_status.clear();
      last_report = Clock::now();
    }
    result.tail.push_back(std::move(line));
    if (result.tail.size() > kLogTailLines) result.tail.pop_front();
  };
  // COLMAP links Qt even for its CLI commands; without a display, Qt aborts unless told to use
  // the offscreen platform.
  const ProcessResult process = RunProcess(colmap, args, {"QT_QPA_PLATFORM=offscreen"}, [&](std::string_view chunk) {
    log.write(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    log.flush();  // so the log is useful while a long step runs
    if (!log) throw IoError(log_path.string(), "cannot write the log (disk full?)");
    for (const char c : chunk) {
      // COLMAP rewrites some lines with '\r'; either ends a line for us.
      if (c == '\n' || c == '\r') {
        handle_line(std::move(partial));
        partial.clear();
      } else if (partial.size() < 4096) {  // bounded even if a tool never ends a line
        partial += c;
      }
    }
  });
  handle_line(std::move(partial));
  // The last status of a step (e.g. 12/12 images) is worth showing even if it came fast.
  if (!pending_status.empty()) Report(options, stage + ": " + pending_status);
  result.exit_code = process.exit_code;
  result.signal = process.signal;
  log << "[perf " << Timestamp() << "] "
      << (result.signal ? StrCat("killed by signal ", result.signal)
                        : StrCat("exit code ", result.exit_code))
      << "\n"
      << std::flush;
  return result;
}

[[noreturn]] void ThrowStepFailed(const std::string& step, const StepResult& r,
                                  const fs::path& log_path) {
  std::string problem = r.signal ? StrCat("colmap ", step, " was killed by signal ", r.signal, " (",
                                          strsignal(r.signal), ")")
                                 : StrCat("colmap ", step, " failed with exit code ", r.exit_code);
  problem += StrCat("; last lines of ", log_path.string(), ":");
  for (const auto& line : r.tail) problem += "\n  | " + line;
  std::string hint = StrCat("see the full log in ", log_path.string());
  if (r.signal == SIGKILL)
    hint +=
        "; a kill by signal 9 is often the out-of-memory killer: try a smaller --max-image-size";
  throw IoError(log_path.string(), problem, hint);
}

// --------------------------------------------------------------------------------------------
// Progress parsers for the three steps (COLMAP 3.8 output).

ProgressParser ExtractionParser() {
  static const std::regex re(R"(Processed file \[(\d+)/(\d+)\])");
  return [](const std::string& line) -> std::optional<std::string> {
    std::smatch m;
    if (!std::regex_search(line, m, re)) return std::nullopt;
    return StrCat(m[1].str(), "/", m[2].str(), " images");
  };
}

ProgressParser ExhaustiveParser() {
  static const std::regex re(R"(Matching block \[(\d+)/(\d+), (\d+)/(\d+)\])");
  return [](const std::string& line) -> std::optional<std::string> {
    std::smatch m;
    if (!std::regex_search(line, m, re)) return std::nullopt;
    const long a = std::stol(m[1]), b = std::stol(m[2]), c = std::stol(m[3]), d = std::stol(m[4]);
    return StrCat("block ", (a - 1) * d + c, "/", b * d);
  };
}

ProgressParser SequentialParser() {
  static const std::regex re(R"(Matching image \[(\d+)/(\d+)\])");
  return [](const std::string& line) -> std::optional<std::string> {
    std::smatch m;
    if (!std::regex_search(line, m, re)) return std::nullopt;
    return StrCat(m[1].str(), "/", m[2].str(), " images");
  };
}

ProgressParser MapperParser(int num_images) {
  static const std::regex re(R"(Registering image #\d+ \((\d+)\))");
  return [num_images](const std::string& line) -> std::optional<std::string> {
    std::smatch m;
    if (!std::regex_search(line, m, re)) return std::nullopt;
    return StrCat(m[1].str(), "/", num_images, " images registered");
  };
}

// --------------------------------------------------------------------------------------------
// Models

struct ModelCounts {
  int num_images = 0;
  int num_points = 0;
};

// The record count at the start of a COLMAP binary file (uint64, little-endian). Reading only
// the header keeps model selection independent of the full reader and cheap for big models.
std::optional<uint64_t> ReadBinaryCount(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char bytes[8];
  if (!in.read(reinterpret_cast<char*>(bytes), sizeof bytes)) return std::nullopt;
  uint64_t n = 0;
  for (int i = 7; i >= 0; --i) n = (n << 8) | bytes[i];
  return n;
}

// Counts of a binary model in `dir`, or nullopt if it is not a complete one.
std::optional<ModelCounts> ReadModelCounts(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_regular_file(dir / "cameras.bin", ec)) return std::nullopt;
  const auto images = ReadBinaryCount(dir / "images.bin");
  const auto points = ReadBinaryCount(dir / "points3D.bin");
  // Counts beyond int range can only come from a garbled file.
  if (!images || !points || *images > INT32_MAX || *points > INT32_MAX) return std::nullopt;
  return ModelCounts{static_cast<int>(*images), static_cast<int>(*points)};
}

// The photos a model holds (COLMAP image names); nullopt when it cannot be read in full.
std::optional<std::set<std::string>> RegisteredNames(const fs::path& dir) {
  try {
    std::set<std::string> names;
    for (const auto& [id, im] : colmap::ReadReconstruction(dir).images) names.insert(im.name);
    return names;
  } catch (const Error&) {
    return std::nullopt;
  }
}

// The inputs a model left out, when its names can be read.
std::optional<std::vector<std::string>> LeftOut(const std::vector<std::string>& inputs, const fs::path& dir) {
  const auto registered = RegisteredNames(dir);
  if (!registered) return std::nullopt;
  std::vector<std::string> out;
  for (const std::string& name : inputs) {
    if (!registered->count(name)) out.push_back(name);
  }
  return out;
}

// "71, 8 and 3", largest first.
std::string ModelSizes(std::vector<int> sizes) {
  std::sort(sizes.rbegin(), sizes.rend());
  std::string out;
  for (size_t i = 0; i < sizes.size(); ++i) out += StrCat(i == 0 ? "" : i + 1 == sizes.size() ? " and " : ", ", sizes[i]);
  return out;
}

// "a.jpg, b.jpg, c.jpg and 4 more"
std::string NameList(const std::vector<std::string>& names, size_t shown = 8) {
  std::string list;
  for (size_t i = 0; i < names.size() && i < shown; ++i) list += (i ? ", " : "") + names[i];
  if (names.size() > shown) list += StrCat(" and ", names.size() - shown, " more");
  return list;
}

// Copies `src` to `dst` so that `dst` is either the old model or the complete new one, never a
// mix: copy into a temporary folder beside it, move the old one aside, move the new one in.
void ReplaceDirectory(const fs::path& src, const fs::path& dst) {
  EnsureWritableDirectory(dst.parent_path());
  const fs::path tmp = TempPathFor(dst);
  const fs::path old = TempPathFor(dst.string() + ".old");
  std::error_code ec;
  fs::remove_all(tmp, ec);
  fs::copy(src, tmp, fs::copy_options::recursive, ec);
  if (ec) {
    fs::remove_all(tmp, ec);
    throw IoError(dst.string(),
                  "cannot copy the sparse model from " + src.string() + ": " + ec.message(),
                  "check free disk space and permissions");
  }
  const bool had_old = fs::exists(dst, ec);
  if (had_old) {
    fs::rename(dst, old, ec);
    if (ec) {
      const std::string why = ec.message();
      fs::remove_all(tmp, ec);
      throw IoError(dst.string(), "cannot replace the existing model: " + why,
                    "remove it by hand and run again");
    }
  }
  fs::rename(tmp, dst, ec);
  if (ec) {
    const std::string why = ec.message();
    if (had_old) fs::rename(old, dst, ec);  // put the old model back
    fs::remove_all(tmp, ec);
    throw IoError(dst.string(), "cannot move the new model into place: " + why,
                  "check that the workspace is writable");
  }
  if (had_old) fs::remove_all(old, ec);
}

}  // namespace

// ----------------------------------------------------------------------------------------------

void SfmOptions::Check() const {
  if (images.empty()) {
    throw InputError(kCommandLine, "--images", "", "no images folder given",
                     "pass the folder that holds your photos");
  }
  if (workspace.empty()) {
    throw InputError(kCommandLine, "--workspace", "", "no workspace folder given",
                     "pass a folder for COLMAP's files and the sparse model");
  }
  if (colmap_binary.empty()) {
    throw InputError(kCommandLine, "--colmap-binary", "", "empty",
                     "pass `colmap` (looked up on PATH) or the path of the binary");
  }
  if (!colmap::FindCameraModel(camera_model)) {
    throw InputError(kCommandLine, "--camera-model", camera_model, "not a COLMAP camera model",
                     "use one of SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, "
                     "OPENCV_FISHEYE, FULL_OPENCV (upper case)");
  }
  if (matcher != "auto" && matcher != "exhaustive" && matcher != "sequential") {
    throw InputError(kCommandLine, "--matcher", matcher, "unknown matcher",
                     "use auto, exhaustive or sequential");
  }
  auto check_at_least = [](const char* field, int value, int min, const char* hint) {
    if (value < min) {
      throw InputError(kCommandLine, field, std::to_string(value), StrCat("must be at least ", min),
                       hint);
    }
  };
  check_at_least("--exhaustive-max-images", exhaustive_max_images, 0,
                 "0 always uses the sequential matcher in auto mode");
  check_at_least("--sequential-overlap", sequential_overlap, 1,
                 "how many following photos each photo is matched with, e.g. 10");
  check_at_least("--max-image-size", max_image_size, 1, "longest side in pixels, e.g. 1600");
  check_at_least("--max-num-features", max_num_features, 1, "features per image, e.g. 8192");
  check_at_least("--min-registered-images", min_registered_images, 2,
                 "a model needs at least two images");
  if (num_threads != -1 && num_threads < 1) {
    throw InputError(kCommandLine, "--num-threads", std::to_string(num_threads),
                     "must be -1 (all cores) or at least 1");
  }
}

SfmResult RunSfm(const SfmOptions& options) {
  options.Check();
  const Clock::time_point start = Clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };

  SfmResult result;
  const std::vector<std::string> inputs = ListInputImages(options.images);
  result.num_input_images = static_cast<int>(inputs.size());
  result.sparse_dir = options.workspace / "sparse" / "0";

  if (!options.force) {
    if (const auto counts = ReadModelCounts(result.sparse_dir)) {
      Report(options, StrCat("sfm: skipped, ", result.sparse_dir.string(), " already exists (",
                             counts->num_images, " images, ", counts->num_points,
                             " points); use --force to run COLMAP again"));
      result.num_registered_images = counts->num_images;
      result.num_points = counts->num_points;
      result.seconds = elapsed();
      return result;
    }
  }

  const fs::path colmap = FindColmap(options.colmap_binary);
  const fs::path colmap_dir = options.workspace / "colmap";
  EnsureWritableDirectory(colmap_dir);
  const fs::path log_path = colmap_dir / "colmap.log";
  const fs::path database = colmap_dir / "database.db";
  const fs::path models_dir = colmap_dir / "sparse";

  // Start from scratch: COLMAP silently keeps the cameras and features already in a database
  // (so a changed --camera-model or --max-image-size would not take effect), and model folders
  // from an earlier run would compete with the new ones.
  std::error_code ec;
  for (const char* suffix : {"", "-shm", "-wal"}) fs::remove(database.string() + suffix, ec);
  fs::remove_all(models_dir, ec);
  EnsureWritableDirectory(models_dir);

  std::ofstream log(log_path, std::ios::app | std::ios::binary);
  if (!log) {
    throw IoError(log_path.string(),
                  StrCat("cannot open the log for writing: ", std::strerror(errno)),
                  "check that the workspace is writable");
  }

  const std::string threads = std::to_string(options.num_threads);
  const int n = result.num_input_images;

  // (a) Features. CPU SIFT: this build of COLMAP has no CUDA, and GPU SIFT would need an
  // OpenGL context that a headless machine lacks.
  // With a shared camera, one per group of photos that agree on size and EXIF camera
  // (camera_groups.h): each group's extraction run (its own image list) adds one camera.
  // The photos' headers, read once: for the camera groups, and beyond the exhaustive limit for
  // the capture order (b).
  const bool order_matters = options.matcher == "auto" && n > options.exhaustive_max_images;
  std::vector<std::optional<CameraTags>> tags;
  if (options.single_camera || order_matters) tags = ReadPhotoTags(options.images, inputs);
  std::vector<CameraGroup> groups;
  if (options.single_camera) {
    groups = GroupByCamera(inputs, tags);
    Report(options, "sfm: " + DescribeGroups(groups));
  }
  Report(options, StrCat("sfm: extracting features from ", n, " images (", colmap.string(), ")"));
  const auto extract = [&](const std::vector<std::string>& list_args) {
    std::vector<std::string> args = {"feature_extractor", "--database_path", database.string(), "--image_path",
                                     options.images.string(), "--ImageReader.camera_model", options.camera_model,
                                     "--ImageReader.single_camera", options.single_camera ? "1" : "0",
                                     "--SiftExtraction.use_gpu", "0", "--SiftExtraction.max_image_size",
                                     std::to_string(options.max_image_size), "--SiftExtraction.max_num_features",
                                     std::to_string(options.max_num_features), "--SiftExtraction.num_threads", threads};
    args.insert(args.end(), list_args.begin(), list_args.end());
    const StepResult r = RunColmapStep(colmap, args, "features", ExtractionParser(), options, log, log_path);
    if (r.signal || r.exit_code != 0) ThrowStepFailed("feature_extractor", r, log_path);
  };
  if (groups.size() > 1) {
    for (size_t g = 0; g < groups.size(); ++g) {
      const fs::path list = colmap_dir / StrCat("camera_", g + 1, "_images.txt");
      std::string text;
      for (const std::string& name : groups[g].names) text += name + "\n";
      WriteFileAtomically(list, text);
      extract({"--image_list_path", list.string()});
    }
  } else {
    extract({});
  }

  // (b) Matching. Exhaustive is quadratic in the number of images but robust to any capture
  // order; sequential assumes photos were taken in order (a walk around the object).
  bool exhaustive = options.matcher == "exhaustive" ||
                    (options.matcher == "auto" && n <= options.exhaustive_max_images);
  if (order_matters) {
    // Beyond the exhaustive limit: do the photos' capture times say the names are in order?
    const CaptureOrder order = OrderFromTags(tags);
    Report(options, "sfm: " + order.Describe());
    exhaustive = order.Known() && !order.NamesFollowTime();
  }
  // A matcher's arguments with the SIFT matching settings every matching step shares.
  const auto with_sift_matching = [&](std::vector<std::string> args) {
    args.insert(args.end(), {"--SiftMatching.use_gpu", "0", "--SiftMatching.num_threads", threads});
    return args;
  };
  {
    std::vector<std::string> args;
    ProgressParser parser;
    if (exhaustive) {
      Report(options, StrCat("sfm: matching all ", n * (n - 1) / 2, " pairs (exhaustive)"));
      args = {"exhaustive_matcher", "--database_path", database.string()};
      parser = ExhaustiveParser();
    } else {
      Report(options, StrCat("sfm: matching each image with its ", options.sequential_overlap,
                             " neighbours (sequential)"));
      args = {"sequential_matcher",
              "--database_path",
              database.string(),
              "--SequentialMatching.overlap",
              std::to_string(options.sequential_overlap),
              "--SequentialMatching.quadratic_overlap",
              "1"};
      parser = SequentialParser();
    }
    const StepResult r = RunColmapStep(colmap, with_sift_matching(args), "matching", parser, options, log, log_path);
    if (r.signal || r.exit_code != 0) {
      ThrowStepFailed(exhaustive ? "exhaustive_matcher" : "sequential_matcher", r, log_path);
    }
  }

  // (c) Incremental mapping. COLMAP writes one numbered folder per disconnected model; the one
  // with the most images is the scene, the others are fragments it could not attach.
  const std::string too_few_hint =
      "photos need more overlap (each point seen in 3+ photos, neighbours sharing 60-80% of the "
      "view), more texture, or more photos; if they were not taken in order, try --matcher "
      "exhaustive";
  std::optional<fs::path> best_dir;
  ModelCounts best;
  std::vector<int> model_sizes;  // photos in each model COLMAP made
  bool no_initial_pair = false;
  const auto map = [&] {
    Report(options, "sfm: mapping (incremental reconstruction)");
    fs::remove_all(models_dir, ec);
    EnsureWritableDirectory(models_dir);
    best_dir.reset();
    best = {};
    model_sizes.clear();
    const StepResult r = RunColmapStep(
        colmap,
        {"mapper", "--database_path", database.string(), "--image_path", options.images.string(),
         "--output_path", models_dir.string(), "--Mapper.num_threads", threads},
        "mapping", MapperParser(n), options, log, log_path);
    // COLMAP 3.8 exits with 1 when no initial pair could be found: a property of the photos,
    // not a failure of the tool.
    no_initial_pair = !r.signal && r.exit_code != 0 && r.saw("failed to create sparse model");
    if ((r.signal || r.exit_code != 0) && !no_initial_pair) ThrowStepFailed("mapper", r, log_path);
    for (const auto& entry : fs::directory_iterator(models_dir, ec)) {
      const std::string name = entry.path().filename().string();
      if (!entry.is_directory() || name.empty() || name.find_first_not_of("0123456789") != std::string::npos) continue;
      const auto counts = ReadModelCounts(entry.path());
      if (!counts) continue;
      model_sizes.push_back(counts->num_images);
      if (!best_dir || counts->num_images > best.num_images ||
          (counts->num_images == best.num_images && counts->num_points > best.num_points)) {
        best_dir = entry.path();
        best = *counts;
      }
    }
  };
  map();
  // Sequential matching assumed the photos were taken in order (file names give no other clue
  // when EXIF is stripped). A model of fewer than half of them says they were not: match the
  // remaining pairs (COLMAP keeps the pairs already matched) and map again.
  if (!exhaustive && options.matcher == "auto" && best.num_images < n / 2) {
    Report(options, StrCat("sfm: sequential matching put only ", best.num_images, " of ", n,
                           " photos in a model, so they were not taken in order: matching every pair and mapping again"));
    const StepResult r = RunColmapStep(colmap, with_sift_matching({"exhaustive_matcher", "--database_path", database.string()}),
                                       "matching", ExhaustiveParser(), options, log, log_path);
    if (r.signal || r.exit_code != 0) ThrowStepFailed("exhaustive_matcher", r, log_path);
    exhaustive = true;
    map();
  }
  if (!best_dir && no_initial_pair) {
    throw InputError(options.images.string(), "registered images", StrCat("0 of ", n),
                     "COLMAP could not reconstruct any part of the scene (no pair of photos "
                     "with enough matches; see " + log_path.string() + ")",
                     too_few_hint);
  }
  if (!best_dir || best.num_images < options.min_registered_images) {
    throw InputError(
        options.images.string(), "registered images", StrCat(best.num_images, " of ", n),
        StrCat("too few images registered (at least ", options.min_registered_images,
               " needed; largest of ", model_sizes.size(), " models in ", models_dir.string(), ")"),
        too_few_hint);
  }

  // (d) Sequential matching misses photos taken out of order: match those left out with every
  // other photo and register them into the model (COLMAP's image_registrator), then adjust.
  if (!exhaustive && options.second_pass && best.num_images < n) {
    if (const auto missing = LeftOut(inputs, *best_dir); missing && !missing->empty()) {
      const fs::path pairs = colmap_dir / "second_pass_pairs.txt";
      std::string text;
      int64_t num_pairs = 0;
      const std::set<std::string> missing_set(missing->begin(), missing->end());
      for (const std::string& a : *missing) {
        for (const std::string& b : inputs) {
          if (a == b || (missing_set.count(b) && b < a)) continue;  // each pair once
          text += a + " " + b + "\n";
          ++num_pairs;
        }
      }
      WriteFileAtomically(pairs, text);
      Report(options, StrCat("sfm: ", best.num_images, "/", n, " images registered after sequential matching; matching the ",
                             missing->size(), " left out with every other photo (", num_pairs, " pairs)"));
      const fs::path second = models_dir / "second_pass";
      EnsureWritableDirectory(second);
      bool ok = true;
      const auto step = [&](const std::vector<std::string>& args, const std::string& stage, const ProgressParser& parse) {
        if (!ok) return;
        const StepResult r = RunColmapStep(colmap, args, stage, parse, options, log, log_path);
        ok = !r.signal && r.exit_code == 0;
        if (!ok) Report(options, StrCat("sfm: ", args.front(), " failed (see ", log_path.string(), "); keeping the first model"));
      };
      step(with_sift_matching({"matches_importer", "--database_path", database.string(), "--match_list_path",
                               pairs.string(), "--match_type", "pairs"}),
           "matching", ExhaustiveParser());
      step({"image_registrator", "--database_path", database.string(), "--input_path", best_dir->string(),
            "--output_path", second.string(), "--Mapper.num_threads", threads},
           "registering", MapperParser(n));
      step({"bundle_adjuster", "--input_path", second.string(), "--output_path", second.string()}, "adjusting",
           [](const std::string&) { return std::optional<std::string>(); });
      const auto counts = ok ? ReadModelCounts(second) : std::nullopt;
      if (counts && counts->num_images > best.num_images) {
        *std::max_element(model_sizes.begin(), model_sizes.end()) = counts->num_images;  // it grew
        best_dir = second;
        best = *counts;
      }
    }
  }

  ReplaceDirectory(*best_dir, result.sparse_dir);
  result.num_registered_images = best.num_images;
  result.num_points = best.num_points;
  if (const auto missing = LeftOut(inputs, result.sparse_dir)) result.left_out = *missing;
  result.seconds = elapsed();
  Report(
      options,
      StrCat("sfm: ", best.num_images, "/", n, " images registered, ", best.num_points, " points",
             model_sizes.size() > 1 ? StrCat(" (the largest of ", model_sizes.size(), " models of ", ModelSizes(model_sizes), " photos)")
                                    : "",
             ", in ",
             static_cast<int>(result.seconds + 0.5), " s -> ", result.sparse_dir.string()));
  if (!result.left_out.empty()) Report(options, "sfm: left out: " + NameList(result.left_out));
  if (best.num_images < 0.9 * n) {
    Report(options, StrCat("sfm: warning: only ", best.num_images, " of ", n, " photos (",
                           static_cast<int>(100.0 * best.num_images / n), " %) are in the model; ",
                           exhaustive ? "try more features (--max-num-features) or larger images (--max-image-size)"
                                      : "try --matcher exhaustive (slower, order-free)",
                           ", or add photos that overlap those left out"));
  }
  return result;
}

}  // namespace perf
