// `perf sfm`: photos -> COLMAP sparse model by running the `colmap` CLI (CPU SIFT, headless):
// feature_extractor, a matcher (exhaustive for small sets, sequential beyond), mapper, and after
// sequential matching a second pass for the photos left out, and more passes while they add
// photos; then the largest model becomes
// WORKSPACE/sparse/0, and the photos it left out are named. COLMAP's own output goes to WORKSPACE/colmap/colmap.log.
#pragma once

#include <algorithm>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace perf {

struct SfmOptions {
  std::filesystem::path images;     // folder of photos (searched recursively by colmap)
  std::filesystem::path workspace;  // gets colmap/ (database, log, all models) and sparse/0
  std::string colmap_binary = "colmap";  // name on PATH or a path
  // COLMAP camera model for extraction. SIMPLE_RADIAL (one focal length, one distortion term):
  // bonsai's every-pair matches mapped with OPENCV gave wrong models twice of two (54-59 of 84
  // photos, fx and fy 5 % apart), with SIMPLE_RADIAL 84 of 84 in a third of the time and 1.7 dB
  // above the shipped model at one budget (docs/tuning.md "One focal length for mapping").
  std::string camera_model = "SIMPLE_RADIAL";
  // Known intrinsics of every photo, in camera_model's parameter order, comma-separated
  // (ImageReader.camera_params; COLMAP starts from them and refines them); empty: from EXIF or a
  // guess. The repair (ghost_repair.h) passes the given model's.
  std::string camera_params;
  // One camera per group of photos that agree on size and EXIF camera (camera_groups.h; one
  // for all when they all agree); false: one per image.
  bool single_camera = true;
  // Matcher: "auto" (exhaustive up to exhaustive_max_images, else sequential unless EXIF capture
  // times go against the file names: capture_order.h), "exhaustive", "sequential". CPU exhaustive matching costs ~0.28 s per pair on 2 cores (84 photos: 16.5 min).
  // With SIMPLE_RADIAL bonsai's 84 photos matched in sequence mapped right 3 times of 3, from every
  // pair 1 of 2 (docs/tuning.md "One focal length for mapping"). Under a time budget (seconds_left),
  // auto matches every pair only where that takes at most half the time left.
  std::string matcher = "auto";
  int exhaustive_max_images = 40;
  int sequential_overlap = 10;           // SequentialMatching.overlap (quadratic overlap on)
  // After sequential matching, match the photos the model left out with every other photo and
  // register them into it (matches_importer, image_registrator, bundle_adjuster).
  bool second_pass = true;
  // After the second pass, photos still left out are tried again as the model grows (points
  // triangulated, then registered again), at most this many more passes, until one adds none.
  int max_more_passes = 4;
  int max_image_size = 1600;             // SiftExtraction.max_image_size
  int max_num_features = 8192;           // SiftExtraction.max_num_features
  // A photo is placed (mapper, registration passes) only on at least this many inlier matches
  // (0: max(30, max_num_features / 80), 102 at 8192 features) and this fraction of its matches as
  // inliers (COLMAP's own: 30 and 0.25). Bonsai's every-pair matches mapped with COLMAP's values put
  // a stretch of photos in a ghost; with these 83 of 84 photos were in place (docs/tuning.md).
  int min_pose_inliers = 0;              // Mapper.abs_pose_min_num_inliers
  double min_pose_inlier_ratio = 0.4;    // Mapper.abs_pose_min_inlier_ratio
  int MinPoseInliers() const { return min_pose_inliers > 0 ? min_pose_inliers : std::max(30, max_num_features / 80); }
  int num_threads = -1;                  // -1: all cores
  int min_registered_images = 3;         // fewer is an error
  bool force = false;                    // re-run even if a sparse model exists
  // A COLMAP step that prints nothing for this long is stopped and reported as stuck (its
  // slowest steps print at least every few minutes on 2 cores); 30 minutes.
  double idle_timeout_seconds = 1800;
  // Looks at the model made (its folder) and says why it looks wrong, or returns "" (empty: no
  // check). Where it looks wrong after sequential matching, every pair is matched and the photos
  // mapped again; the model from every pair replaces it where it does not look wrong. perf run and
  // perf sfm pass ObjectModelDoubt (model_check.h): a ghost, or cameras that do not look at a
  // common point as an object capture's do.
  std::function<std::string(const std::filesystem::path&)> check_model;
  // With a time budget (perf run --time-budget): the seconds it leaves. A remake from every pair
  // (above) that would take longer, at the rate sequential matching ran, is said to pass the
  // budget, and runs: a model that looks wrong is not worth fitting in time. Unset: none.
  std::function<double()> seconds_left;
  // Called with one line of progress per step (stage name and a short status).
  std::function<void(const std::string&)> progress;
  // Called while a COLMAP step runs, at least every quarter second (common/subprocess.h); throwing
  // (Ctrl-C: Interrupted) ends the step with its process group. Empty: nothing.
  std::function<void()> check_stop;

  // Throws InputError naming the bad option.
  void Check() const;
};

struct SfmResult {
  std::filesystem::path sparse_dir;  // WORKSPACE/sparse/0
  int num_input_images = 0;
  int num_registered_images = 0;
  int num_points = 0;
  std::vector<std::string> left_out;  // input photos not in the model (empty when unknown)
  std::vector<int> passes;            // the photos each registration pass added (the second on)
  bool exhaustive = false;            // every pair was matched (by choice or after sequential)
  std::string doubt;                  // check_model's word on the model installed ("": none)
  double seconds = 0;
  bool kept = false;  // the model already at sparse/0 was kept (made from these photos; no --force)
};

// Throws IoError/InputError with a clear message when colmap is missing, a step fails (with the
// tail of its log) or too few images register.
SfmResult RunSfm(const SfmOptions& options);

}  // namespace perf
