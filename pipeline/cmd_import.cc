#include <CLI/CLI.hpp>
#include <iostream>

#include "common/errors.h"
#include "pipeline/commands.h"
#include "pipeline/progress.h"
#include "sfm_import/box_preview.h"
#include "sfm_import/ghost_repair.h"
#include "sfm_import/importer.h"

namespace perf {
namespace {

Eigen::Vector3d ParseColour(const std::string& s) {
  if (s == "white") return Eigen::Vector3d::Ones();
  if (s == "black") return Eigen::Vector3d::Zero();
  Eigen::Vector3d c;
  char sep1 = 0, sep2 = 0;
  std::istringstream in(s);
  if (in >> c.x() >> sep1 >> c.y() >> sep2 >> c.z() && sep1 == ',' && sep2 == ',' && in.peek() == EOF) {
    return c;
  }
  throw InputError("command line", "--background", s, "not a colour",
                   "use white, black, or R,G,B with components in [0, 1]");
}

Eigen::Vector3d ToVec(const std::vector<double>& v) { return {v[0], v[1], v[2]}; }

}  // namespace

void AddImportCommand(CLI::App& app) {
  struct Args {
    ImportOptions o;
    std::string background = "white";
    std::vector<double> box_center, box_size, shell_radii;
    bool quiet = false;
    bool preview_box = false;
    bool no_repair = false;
  };
  auto args = std::make_shared<Args>();
  ImportOptions& o = args->o;
  CLI::App* cmd = app.add_subcommand(
      "import",
      "Read a COLMAP sparse model (binary or text) or a NeRF transforms.json into a workspace: "
      "undistorted pinhole images, train/test split, bounding box and shells (scene.json).");
  cmd->add_option("--colmap", o.colmap_dir,
                  "COLMAP sparse model folder holding cameras/images/points3D (.bin or .txt), e.g. project/sparse/0");
  cmd->add_option("--images", o.images_dir,
                  "Folder of the photos the model was made from (default: <model>/../../images)");
  cmd->add_option("--nerf", o.nerf_json, "NeRF-synthetic style transforms.json (instead of --colmap)");
  cmd->add_option("-w,--workspace", o.workspace, "Workspace folder to create or update")->required();
  cmd->add_option("--downscale", o.downscale, "Integer downscale of the images (OIIO filtered resize)")
      ->capture_default_str();
  cmd->add_option("--max-size", o.max_size, "Downscale so the longer side is at most this many pixels (instead of --downscale)");
  cmd->add_option("--holdout", o.holdout, "Hold out every N-th image for testing (COLMAP: sorted by name; NeRF: json order, r_0, r_8, ...); 0 for none")
      ->capture_default_str();
  cmd->add_flag("--skip-missing", o.skip_missing, "Import the other images when some in the model are missing on disk");
  cmd->add_flag("--keep-bad-poses", o.keep_bad_poses,
                "Train and score on COLMAP photos whose pose looks wrong too (by default they are marked \"excluded\" in "
                "scene.json and named in a warning)");
  cmd->add_option("--background", args->background,
                  "Colour RGBA photos are composited over: white, black or R,G,B in [0,1]")
      ->capture_default_str();
  cmd->add_option("--box-center", args->box_center, "Override the box centre (world units)")->expected(3);
  cmd->add_option("--box-size", args->box_size, "Override the box side lengths (world units, box frame)")->expected(3);
  cmd->add_flag("--box-axis-aligned", o.box_axis_aligned,
                "Keep the box aligned with the world axes (default for COLMAP: aligned to the cameras' up)");
  cmd->add_option("--shells", o.bounds.num_shells, "Number of environment shells")->capture_default_str();
  cmd->add_option("--shell-radii", args->shell_radii, "Override the shell radii (increasing, world units)");
  cmd->add_option("--min-track-length", o.bounds.min_track_length,
                  "Sparse points seen by fewer images are ignored when placing the box")->capture_default_str();
  AddThreadsOption(cmd, &o.num_threads, 0);
  cmd->add_flag("--preview-box", args->preview_box,
                "Also write WORKSPACE/preview/box_*.png: the box drawn over the held-out views");
  cmd->add_flag("--no-repair", args->no_repair,
                "Import a COLMAP model that holds a ghost group as given (default: make the model again from the photos "
                "with perf sfm into WORKSPACE/repair/ and import that one, from WORKSPACE/sparse_repaired/, where it is "
                "better)");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  cmd->callback([args]() {
    ImportOptions& o = args->o;
    o.background = ParseColour(args->background);
    if (!args->box_center.empty()) o.box_center = ToVec(args->box_center);
    if (!args->box_size.empty()) o.box_size = ToVec(args->box_size);
    if (!args->shell_radii.empty()) o.shell_radii = args->shell_radii;
    const auto lock = LockWorkspace(o.workspace, "import", true);
    Progress progress("import", args->quiet);
    o.progress = [&progress](int done, int total) { progress.Update(done, total, "images"); };
    ImportResult r;
    // A failed import into a new folder leaves no half-filled workspace behind.
    RemoveNewWorkspaceOnFailure(lock.get(), o.workspace, true, [&] {
      o.Check();  // the options before the model is read for its repair
      if (!o.colmap_dir.empty()) {
        RepairOptions ro;
        ro.model = o.colmap_dir;
        ro.images = o.images_dir;
        ro.workspace = o.workspace;
        ro.repair = !args->no_repair;
        ro.threads = o.num_threads;
        ro.say = [&](const std::string& line) {
          if (!args->quiet) std::cout << "import: " << line << "\n" << std::flush;
        };
        const RepairResult repaired = RepairModel(ro);
        o.colmap_dir = repaired.model;
        o.images_dir = repaired.images;
        o.turn_unknown = repaired.TurnUnknown();
      }
      r = RunImport(o);
    });
    progress.Finish();
    if (!args->quiet) std::cout << ImportSummary(r) << "workspace: " << o.workspace.string() << "\n";
    if (args->preview_box) {
      const auto files = WriteBoxPreviews(r.scene, o.workspace);
      if (!args->quiet) std::cout << "box previews: " << (o.workspace / "preview").string() << " (" << files.size() << " images)\n";
    }
  });
}

}  // namespace perf
