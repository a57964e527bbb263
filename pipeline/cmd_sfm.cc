#include <CLI/CLI.hpp>
#include <iostream>

#include "common/errors.h"
#include "pipeline/commands.h"
#include "pipeline/progress.h"
#include "sfm_import/colmap_runner.h"
#include "sfm_import/model_check.h"

namespace perf {

void AddSfmCommand(CLI::App& app) {
  auto o = std::make_shared<SfmOptions>();
  auto quiet = std::make_shared<bool>(false);
  CLI::App* cmd = app.add_subcommand(
      "sfm",
      "Make a COLMAP sparse model from a folder of photos with the colmap CLI (CPU SIFT): "
      "features, matching, mapping. The largest model becomes WORKSPACE/sparse/0; COLMAP's log is "
      "WORKSPACE/colmap/colmap.log. Then run `perf import --colmap WORKSPACE/sparse/0 --images DIR`.");
  cmd->add_option("--images", o->images, "Folder of photos")->required();
  cmd->add_option("-w,--workspace", o->workspace, "Workspace folder")->required();
  cmd->add_option("--camera-model", o->camera_model, "COLMAP camera model for the photos")->capture_default_str();
  cmd->add_flag("--per-image-camera", [o](std::int64_t) { o->single_camera = false; },
                "One camera per photo (default: one per group of photos that agree on size and EXIF make, model and focal "
                "length; one for all when they all agree)");
  cmd->add_option("--matcher", o->matcher,
                  "auto (exhaustive up to --exhaustive-max images; beyond, sequential unless the photos' EXIF capture "
                  "times go against their file names), exhaustive or sequential")
      ->capture_default_str();
  cmd->add_option("--exhaustive-max", o->exhaustive_max_images,
                  "Largest set matched exhaustively by --matcher auto (CPU: ~0.28 s per pair)")->capture_default_str();
  cmd->add_option("--overlap", o->sequential_overlap, "Sequential matching overlap (quadratic overlap on)")
      ->capture_default_str();
  cmd->add_flag("!--no-second-pass", o->second_pass,
                "After sequential matching, do not match the photos left out with every other photo and register them again");
  cmd->add_option("--max-image-size", o->max_image_size, "Longest side used for feature extraction")
      ->capture_default_str();
  cmd->add_option("--max-features", o->max_num_features, "Most SIFT features per image")->capture_default_str();
  cmd->add_option("--min-pose-inliers", o->min_pose_inliers,
                  "A photo is placed only on at least this many inlier matches (0: max(30, max-features / 80); COLMAP's own: 30)")
      ->capture_default_str();
  cmd->add_option("--min-pose-inlier-ratio", o->min_pose_inlier_ratio,
                  "... and this fraction of its matches as inliers (COLMAP's own: 0.25)")
      ->capture_default_str();
  cmd->add_option("--min-registered", o->min_registered_images, "Fewer registered images is an error")
      ->capture_default_str();
  AddThreadsOption(cmd, &o->num_threads, -1);
  cmd->add_option("--colmap-binary", o->colmap_binary, "The colmap executable")->capture_default_str();
  cmd->add_option("--colmap-idle-timeout", o->idle_timeout_seconds,
                  "Seconds a COLMAP step may print nothing before it is stopped as stuck")
      ->capture_default_str();
  cmd->add_flag("--force", o->force, "Run again even if WORKSPACE/sparse/0 exists and was made from these photos");
  cmd->add_flag("-q,--quiet", *quiet, "No progress output");
  cmd->callback([o, quiet]() {
    const auto lock = LockWorkspace(o->workspace, "sfm", true);
    Progress progress("sfm", *quiet);
    o->progress = [&progress](const std::string& line) { progress.Message(line); };
    // COLMAP runs in a process group of its own (common/subprocess.h): Ctrl-C reaches it through us.
    const StopOnCtrlC ctrl_c;
    o->check_stop = [] {
      if (StopRequested().load()) throw Interrupted("COLMAP was stopped; run the same command again to start over");
    };
    o->check_model = ObjectModelDoubtOf;
    SfmResult r;
    RemoveNewWorkspaceOnFailure(lock.get(), o->workspace, false, [&] { r = RunSfm(*o); });
    if (!*quiet) {
      std::cout << "registered " << r.num_registered_images << " of " << r.num_input_images << " images, "
                << r.num_points << " points in " << r.seconds << " s\nmodel: " << r.sparse_dir.string() << "\n";
    }
  });
}

}  // namespace perf
