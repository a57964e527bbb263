// `perf export WORKSPACE` and `perf eval WORKSPACE`.
#include <CLI/CLI.hpp>
#include <iomanip>
#include <iostream>

#include "common/errors.h"
#include "export/evaluate.h"
#include "export/export.h"
#include "pipeline/commands.h"
#include "pipeline/stage_progress.h"

namespace perf {

void AddExportCommand(CLI::App& app) {
  struct Args {
    exporter::ExportOptions o;
    std::string workspace, checkpoint, iso = "auto";
    bool no_masks = false, no_foreground = false, no_volume = false, no_mesh = false, no_renders = false;
    bool quiet = false;
  };
  auto args = std::make_shared<Args>();
  exporter::ExportOptions& o = args->o;
  CLI::App* cmd = app.add_subcommand(
      "export",
      "Write what a reconstruction gives: foreground masks and cut-outs of every photo, an OpenVDB volume, a "
      "coloured mesh (PLY, OBJ, GLB) and renders (held-out views, an orbit), into the workspace.");
  cmd->add_option("workspace", args->workspace, "Workspace folder (reconstructed)")->required();
  cmd->add_option("--checkpoint", args->checkpoint, "Checkpoint to export (default: the last level in WORKSPACE/recon)");
  cmd->add_option("--mask-threshold", o.mask_threshold, "Binary mask where the box opacity reaches this (paper: 0.7)")
      ->capture_default_str();
  cmd->add_flag("--soft-mask-exr", o.soft_mask_exr, "Soft masks as half-float EXR instead of 16-bit PNG");
  cmd->add_flag("--soft-cutout", o.foreground_soft_alpha, "Cut-outs take the soft mask as alpha (default: binary)");
  cmd->add_option("--mask-render-scale", o.mask.render_scale,
                  "Render masks at this multiple of the workspace resolution before mapping them to the photos")
      ->capture_default_str();
  cmd->add_option("--vdb-min-opacity", o.vdb.min_cell_opacity,
                  "Volume: write cells whose opacity across one voxel reaches this")->capture_default_str();
  cmd->add_flag("--houdini", o.vdb.houdini_names, "Volume: name the colour grid Cd (Houdini) instead of color (Blender)");
  cmd->add_flag("--half", o.vdb.half_float, "Volume: store the grids as 16-bit floats");
  cmd->add_option("--iso", args->iso,
                  "Mesh: iso-surface of the opacity across one voxel, in (0, 1), or auto: the level whose "
                  "silhouettes in the training views best match the masks")
      ->capture_default_str();
  cmd->add_option("--min-component", o.mesh_options.min_component_fraction,
                  "Mesh: keep parts with at least this fraction of the largest part's triangles (1: largest only, 0: all)")
      ->capture_default_str();
  cmd->add_option("--mesh-triangles", o.mesh_triangles,
                  "Mesh: simplify to at most this many triangles where the surface allows (0: as extracted)")
      ->capture_default_str();
  cmd->add_option("--orbit-frames", o.orbit.frames, "Orbit renders (0: none)")->capture_default_str();
  cmd->add_option("--orbit-elevation", o.orbit.elevation_degrees, "Orbit height above the box's horizon, degrees")
      ->capture_default_str();
  AddMinBoxOpacityOption(cmd, &o.min_box_opacity, "Renders");
  cmd->add_flag("--no-masks", args->no_masks, "Skip the masks");
  cmd->add_flag("--no-foreground", args->no_foreground, "Skip the cut-outs (they need the original photos)");
  cmd->add_flag("--no-volume", args->no_volume, "Skip volume.vdb");
  cmd->add_flag("--no-mesh", args->no_mesh, "Skip the mesh");
  cmd->add_flag("--no-renders", args->no_renders, "Skip the renders");
  AddDeviceOptions(cmd, &o.device, &o.threads);
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  cmd->callback([args]() {
    exporter::ExportOptions& o = args->o;
    o.workspace = args->workspace;
    o.checkpoint = args->checkpoint;
    o.masks = !args->no_masks;
    o.foreground = !args->no_foreground;
    o.volume = !args->no_volume;
    o.mesh = !args->no_mesh;
    o.renders = !args->no_renders;
    o.auto_iso = args->iso == "auto";
    if (!o.auto_iso) {
      try {
        size_t used = 0;
        o.mesh_options.iso_opacity = std::stod(args->iso, &used);
        if (used != args->iso.size()) throw std::invalid_argument("trailing characters");
      } catch (const std::exception&) {
        throw InputError("command line", "--iso", args->iso, "not a number nor auto",
                         "pass an opacity in (0, 1), e.g. 0.3, or auto");
      }
    }
    const auto lock = LockWorkspace(o.workspace, "export");
    StepProgress progress("export", args->quiet);
    o.progress = [&](const std::string& step, int done, int total) { progress.Update(step, done, total); };
    const exporter::ExportResult r = exporter::RunExport(o);
    progress.Finish();
    if (!r.iso.warning.empty()) std::cerr << "warning: " << r.iso.warning << "\n";
    if (args->quiet) return;
    std::cout << "exported " << r.checkpoint.string() << " into " << o.workspace.string() << " in " << std::fixed
              << std::setprecision(1) << r.seconds << " s\n";
    if (r.masks > 0) {
      std::cout << "  masks/soft, masks/binary: " << r.masks << " photos, mean coverage " << 100 * r.mean_mask_coverage
                << " %\n";
    }
    if (r.foreground > 0) std::cout << "  foreground: " << r.foreground << " RGBA cut-outs\n";
    if (!r.no_mask.empty()) {
      std::cout << "  no masks for " << r.no_mask.size() << " photos left out on import (pose looks wrong):";
      for (const std::string& name : r.no_mask) std::cout << " " << name;
      std::cout << "\n";
    }
    if (o.volume) {
      std::cout << "  volume.vdb: grids " << r.vdb.density_grid << " + " << r.vdb.colour_grid << ", " << r.vdb.active_voxels
                << " of " << r.vdb.total_voxels << " voxels, " << r.vdb.file_bytes / 1024 << " KiB\n";
    }
    if (o.mesh) {
      std::cout << "  mesh.ply / mesh.obj / mesh.glb: " << r.mesh_vertices << " vertices, " << r.mesh_triangles
                << " triangles, " << r.mesh_components_kept << " of " << r.mesh_components_found
                << " parts kept"
                << (r.mesh_triangles_extracted > r.mesh_triangles ? StrCat(" (simplified from ", r.mesh_triangles_extracted, ")")
                                                                  : std::string())
                << "; iso " << r.iso.iso << (r.iso.automatic ? " (chosen)" : "") << ", silhouette IoU "
                << std::setprecision(3) << r.iso.silhouette_iou << std::setprecision(1) << " against the masks\n";
    }
    if (o.renders) std::cout << "  renders/test: " << r.renders << " views, renders/orbit: " << r.orbit_frames << " frames\n";
  });
}

void AddEvalCommand(CLI::App& app) {
  struct Args {
    exporter::EvalOptions o;
    std::string workspace, checkpoint, gt_masks;
    bool no_html = false, quiet = false;
  };
  auto args = std::make_shared<Args>();
  exporter::EvalOptions& o = args->o;
  CLI::App* cmd = app.add_subcommand(
      "eval",
      "Score a reconstruction: PSNR and SSIM of the held-out views (whole and inside our foreground mask), mask IoU "
      "against true masks when there are any; writes WORKSPACE/report.json and report.html.");
  cmd->add_option("workspace", args->workspace, "Workspace folder (reconstructed)")->required();
  cmd->add_option("--checkpoint", args->checkpoint, "Checkpoint to score (default: the last level in WORKSPACE/recon)");
  cmd->add_option("--gt-masks", args->gt_masks, "Folder of true foreground masks, one per photo, named like the photos");
  cmd->add_option("--mask-threshold", o.mask_threshold, "Binary mask where the box opacity reaches this")->capture_default_str();
  AddMinBoxOpacityOption(cmd, &o.min_box_opacity, "Renders");
  cmd->add_flag("--no-html", args->no_html, "Write report.json only");
  AddDeviceOptions(cmd, &o.device, &o.threads);
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  cmd->callback([args]() {
    exporter::EvalOptions& o = args->o;
    o.workspace = args->workspace;
    o.checkpoint = args->checkpoint;
    o.gt_masks = args->gt_masks;
    o.html = !args->no_html;
    const auto lock = LockWorkspace(o.workspace, "eval");
    StepProgress progress("eval", args->quiet);
    o.progress = [&](const std::string& step, int done, int total) { progress.Update(step, done, total); };
    const exporter::EvalResult r = exporter::RunEval(o);
    progress.Finish();
    if (args->quiet) return;
    std::cout << std::fixed << std::setprecision(2) << "held-out views: " << r.views.size() << ", PSNR " << r.mean.psnr
              << " dB, SSIM " << std::setprecision(4) << r.mean.ssim << "; inside the mask: PSNR " << std::setprecision(2)
              << r.mean.psnr_masked << " dB, SSIM " << std::setprecision(4) << r.mean.ssim_masked << "\n";
    if (!r.mask_truth.empty()) {
      std::cout << "masks vs " << r.mask_truth << " (" << r.masks.size() << " images): IoU " << r.pooled.iou
                << ", precision " << r.pooled.precision << ", recall " << r.pooled.recall << " (mean IoU " << r.mean_iou
                << ")\n";
    }
    std::cout << "wrote " << (o.workspace / "report.json").string();
    if (o.html) std::cout << " and " << (o.workspace / "report.html").string();
    std::cout << "\n";
  });
}

}  // namespace perf
