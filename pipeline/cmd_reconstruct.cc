// `perf reconstruct WORKSPACE` and `perf render WORKSPACE`.
#include <CLI/CLI.hpp>
#include <iostream>

#include "common/comm.h"
#include "common/errors.h"
#include "pipeline/cli_choice.h"
#include "pipeline/commands.h"
#include "pipeline/stage_progress.h"
#include "recon_cuda/run/reconstruct.h"
#ifdef PERF_WITH_NCCL
#include "recon_cuda/backends/nccl_comm.h"
#endif
#include "recon_cuda/run/render_views.h"
#ifndef PERF_NO_LIVE_VIEW  // perf_gpu: no viewer (pipeline/CMakeLists.txt)
#include "viewer/live_view.h"
#endif

namespace perf {

namespace {

// The solver's options of `perf reconstruct` (SolverOptions).
void AddSolverOptions(CLI::App* cmd, recon::SolverOptions* solver) {
  cmd->add_option("--max-cg-iterations", solver->max_cg_iterations, "PCG iterations per Gauss-Newton step at most")
      ->capture_default_str();
  AddCostToleranceOption(cmd, &solver->cost_tolerance);
  cmd->add_option("--jtj-ray-stride", solver->jtj_ray_stride,
                  "Subsampled Gauss-Newton: PCG multiplies by J^T J on every k-th ray only (the gradient keeps all "
                  "rays; 1: exact)")
      ->capture_default_str();
  cmd->add_option("--smooth-grid", solver->smooth_grid,
                  "Smoothness between neighbouring grid cells, relative to the photos (1: a pair as stiff as the mean "
                  "cell's data; 0: off; default: 0.3 where the background is learned, 0 where it is fixed)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--smooth-shells", solver->smooth_shells,
                  "Smoothness between neighbouring shell texels, across cube-map seams too, relative to the photos (0: off)")
      ->capture_default_str();
  cmd->add_option("--cg-exit-ratio", solver->cg_exit_ratio, "PCG leaves when |r|^2 falls by less than this factor (paper: 0.85; default inf: never)")
      ->capture_default_str();
  cmd->add_option("--damping", solver->damping, "Levenberg-Marquardt damping of the diagonal (0: Gauss-Newton)")
      ->capture_default_str();
  cmd->add_option("--initial-step", solver->initial_step, "First step length tried by the line search (paper: 1)")
      ->capture_default_str();
  cmd->add_option("--diagonal-floor", solver->diagonal_floor,
                  "Preconditioner floor relative to the largest diag(J^T J) entry")->capture_default_str();
  cmd->add_option("--line-search-stride", solver->line_search_ray_stride,
                  "Evaluate the line search on every k-th ray")->capture_default_str();
  cmd->add_option("--lr-colour", solver->adam.lr_colour, "Adam learning rate of colours and shell opacities")
      ->capture_default_str();
  cmd->add_option("--lr-density", solver->adam.lr_density, "Adam learning rate of densities")->capture_default_str();
}

// --sh-degree and the level its bands join. The command solves degree 1 at the last level by
// default, as every `perf run` preset does (ReconstructOptions keeps the paper's view-independent
// 0): on lego 200x200 it passes degree 0's final PSNR sooner and ends 1.9 dB above it (docs/tuning.md
// "View dependence by default in perf reconstruct").
void AddViewDependenceOptions(CLI::App* cmd, recon::ReconstructOptions& o) {
  o.sh_degree = 1;
  AddShDegreeOption(cmd, &o.sh_degree);
  AddShFromLevelOption(cmd, &o.sh_from_level);
}

// --refine-poses and its settings.
void AddPoseOptions(CLI::App* cmd, recon::ReconstructOptions& o) {
  AddCameraRefinementOptions(cmd, &o.poses, &o.refine_focal);
  cmd->add_option("--refine-poses-from", o.refine_poses_from,
                  "With --refine-poses: the first level that refines them, 1 to 6 (earlier levels hold the "
                  "imported poses)")
      ->capture_default_str();
  cmd->add_option("--pose-prior", o.pose_prior,
                  "Weight of the prior that keeps the refined cameras near the imported ones, relative to the photos "
                  "(default: 0.03; 0.1 with --refine-intrinsics focal)");
}

// perf reconstruct's command line (AddReconstructCommand) and its run (RunReconstruct).
struct ReconstructArgs {
  recon::ReconstructOptions o;
  std::string workspace;
  std::string solver = "gn";
  bool no_aux = false, no_alpha = false, no_pyramid = false, no_hold = false, no_grow = false, quiet = false;
#ifndef PERF_NO_LIVE_VIEW
  bool view = false;
  viewer::ViewOptions view_options;
#endif
};

// perf reconstruct with the parsed options.
void RunReconstruct(ReconstructArgs& args) {
  recon::ReconstructOptions& o = args.o;
  o.workspace = args.workspace;
  if (args.solver == "gn") {
    o.solver.type = recon::SolverType::kGaussNewton;
  } else if (args.solver == "adam") {
    o.solver.type = recon::SolverType::kAdam;
  } else {
    throw InputError("command line", "--solver", args.solver, "unknown solver", "use gn or adam");
  }
  o.solver.adam.lr_opacity = o.solver.adam.lr_colour;
  if (args.no_aux) o.residuals.lambda = o.residuals.alpha_weight = 0;
  if (args.no_pyramid) o.pyramid = false;
  if (args.no_grow) o.grow_box = false;
  if (args.no_hold) o.solver.hold_at_bounds = false;
  if (args.no_alpha) o.residuals.use_alpha = false;
  // Under mpirun every rank fits its share of the photos; rank 0 holds the lock, writes and reports.
  o.comm = &World();
#ifdef PERF_WITH_NCCL
  o.device_comm = [](Communicator& host) { return recon::MakeNcclCommunicator(host); };
#endif
  const bool root = o.comm->IsRoot();
  std::unique_ptr<WorkspaceLock> lock;
  if (root) lock = LockWorkspace(o.workspace, "reconstruct");
  Progress progress("reconstruct", args.quiet || !root);
#ifndef PERF_NO_LIVE_VIEW
  const std::unique_ptr<viewer::LiveView> live =
      StartLiveView(args.view, root, args.view_options, o.workspace, "reconstruct");
  if (live) {
    o.preview_every = 1;
    o.on_volume = [&live](recon::Checkpoint volume, int iteration) { live->Volume(std::move(volume), iteration); };
  }
#endif
  o.on_event = [&](const recon::ReconstructOptions::Event& e) {
    if (StopRequested().load()) {
#ifndef PERF_NO_LIVE_VIEW
      if (live) live->End("stopped");
#endif
      throw Interrupted("the workspace is consistent; run the same command with --resume to go on");
    }
    ShowReconstructEvent(progress, e);
#ifndef PERF_NO_LIVE_VIEW
    if (live && e.message.empty()) live->Iteration(e.level, e.levels, e.iteration, e.iterations);
#endif
  };
  const StopOnCtrlC ctrl_c;
  const recon::ReconstructResult r = recon::Reconstruct(o);
  progress.Finish();
  if (!args.quiet && root) std::cout << recon::ReconstructSummary(r);
}

}  // namespace

void AddReconstructCommand(CLI::App& app) {
  auto args = std::make_shared<ReconstructArgs>();
  recon::ReconstructOptions& o = args->o;
  CLI::App* cmd = app.add_subcommand(
      "reconstruct",
      "Fit the voxel grid and environment shells to a workspace made by perf import: hierarchical "
      "Gauss-Newton with preconditioned CG, coarse to fine, checkpointed after every level. Under mpirun "
      "(mpirun -np N perf reconstruct WS) the ranks split the photos and sum every pass; rank 0 writes.");
  cmd->add_option("workspace", args->workspace, "Workspace folder (made by perf import)")->required();
  AddDeviceOptions(cmd, &o.device, &o.threads);
  cmd->add_option("--levels", o.levels,
                  "Hierarchy levels, each doubling the resolution (0: the fewest whose finest cell is about one pixel "
                  "of the median photo, within --max-resolution and memory)")
      ->capture_default_str();
  cmd->add_option("--max-resolution", o.max_resolution,
                  StrCat("Without --levels: the finest grid has at most this many cells across (0: ",
                         recon::DefaultMaxResolution(recon::BackendKind::kCpu), " on CPU, ",
                         recon::DefaultMaxResolution(recon::BackendKind::kCuda), " on GPU)"))
      ->capture_default_str();
  cmd->add_option("--start-resolution", o.start_resolution, "Grid cells per axis (and texels per face side) at level 1")
      ->capture_default_str();
  cmd->add_option("--iterations", o.iterations,
                  "Solver iterations per level (Gauss-Newton iterations, at most: see --cost-tolerance; or Adam steps)")
      ->capture_default_str();
  cmd->add_option("--level-iterations", o.level_iterations,
                  "Solver iterations of each level, comma-separated (e.g. 4,4,4,8); levels not listed run --iterations")
      ->delimiter(',');
  cmd->add_option("--solver", args->solver, "gn (Gauss-Newton, the paper's) or adam (first-order baseline)")
      ->capture_default_str();
  cmd->add_option("--seed", o.init.seed, "Seed of the random start and of the jitter")->capture_default_str();
  cmd->add_flag("--resume", o.resume, "Continue after the last checkpoint in WORKSPACE/recon");
  cmd->add_option("--preview-every", o.preview_every,
                  "Write WORKSPACE/preview/recon_l<level>_i<iteration>.png of a held-out view every K iterations")
      ->capture_default_str();
  cmd->add_option("--eval-every", o.eval_every, "Log the held-out PSNR every K iterations (0: at the end of each level)")
      ->capture_default_str();
  cmd->add_option("--lambda", o.residuals.lambda, "Weight of the paper's auxiliary opacity residual")
      ->capture_default_str();
  cmd->add_option("--alpha-weight", o.residuals.alpha_weight,
                  "Weight of the opacity residual that fits the photos' alpha (used instead of --lambda's term "
                  "where every photo had alpha)")
      ->capture_default_str();
  cmd->add_flag("--no-aux", args->no_aux, "Switch the opacity residual off (either kind)");
  cmd->add_option("--robust", o.residuals.robust_scale,
                  "Robust colour loss: Cauchy with this scale (a ray whose colour error is this large gets half "
                  "the weight it has in least squares), solved by reweighting inside Gauss-Newton from the second level "
                  "on; 0: least squares")
      ->capture_default_str();
  cmd->add_option("--stop-transmittance", o.residuals.stop_transmittance,
                  "End a ray's march once its transmittance is below this (0: march the whole box)")
      ->capture_default_str();
  cmd->add_flag("--no-pyramid", args->no_pyramid, "Fit full-resolution photos at every level");
  cmd->add_flag("--no-grow-box", args->no_grow,
                "Only warn where the first level's density reaches a side or top face of the box (default: grow "
                "the box there by a quarter, write it to scene.json and fit the first level again, at most twice)");
  cmd->add_flag("--dense", o.dense,
                "Keep every level's grid dense (default: levels after the first store only the 8^3 bricks near "
                "what the level before fitted)");
  cmd->add_option("--sparse-min-opacity", o.occupancy.min_opacity,
                  "Sparse levels keep the bricks near cells of at least this opacity at the level before")
      ->check(CLI::Range(0.0f, 1.0f))
      ->capture_default_str();
  cmd->add_option("--sparse-dilation", o.occupancy.dilation,
                  "Sparse levels: the kept cells grow by this many cells of the level before")
      ->check(CLI::Range(0, 8))
      ->capture_default_str();
  AddSolverOptions(cmd, &o.solver);
  cmd->add_option("--init-opacity", o.init.box_opacity,
                  "Opacity of the box across its shortest side at the start")->capture_default_str();
  cmd->add_flag("--init-shells-mean", o.init_shells_from_photos, "Shells start at the photos' mean colour (else random)");
  using recon::BackgroundChoice;
  AddChoiceOption(cmd, "--background", &o.background,
                  {{"auto", BackgroundChoice::kAuto}, {"fixed", BackgroundChoice::kFixed},
                   {"learn", BackgroundChoice::kLearn}},
                  "Shells: learn them, or keep them fixed at scene.json's background colour (auto: fixed when "
                  "every photo had alpha)");
  using recon::ExposureChoice;
  AddChoiceOption(cmd, "--exposure", &o.exposure,
                  {{"auto", ExposureChoice::kAuto}, {"on", ExposureChoice::kOn}, {"off", ExposureChoice::kOff}},
                  "Solve a gain and an offset per colour channel for every training photo (auto: for COLMAP "
                  "photos, not for NeRF json scenes); held-out views take the blend of their two nearest training "
                  "photos' (by camera centre)");
  AddPoseOptions(cmd, o);
  AddViewDependenceOptions(cmd, o);
  cmd->add_option("--exposure-prior", o.solver.exposure_prior,
                  "Weight of the prior that keeps the photos' exposures near the identity, relative to the photos")
      ->capture_default_str();
  cmd->add_flag("--no-alpha", args->no_alpha,
                "Ignore the photos' alpha: the opacity residual is the paper's auxiliary term (default: where every "
                "photo had alpha, the box opacity fits it)");
  cmd->add_flag("--pixel-jitter", o.residuals.pixel_jitter,
                "Move every training ray to a random point of its pixel each iteration (default: pixel centres)");
  cmd->add_flag("--no-hold-at-bounds", args->no_hold,
                "Let CG move parameters at a bound of their range that the gradient pushes out (plain projected GN)");
  AddMinBoxOpacityOption(cmd, &o.min_box_opacity, "Previews and held-out PSNR");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
#ifndef PERF_NO_LIVE_VIEW
  AddLiveViewOptions(cmd, &args->view, &args->view_options.port, &o.preview_image, "it stops with the solve");
#endif
  cmd->callback([args]() { RunReconstruct(*args); });
}

void AddRenderCommand(CLI::App& app) {
  struct Args {
    recon::RenderViewsOptions o;
    std::string workspace, checkpoint, out;
    bool quiet = false;
  };
  auto args = std::make_shared<Args>();
  recon::RenderViewsOptions& o = args->o;
  CLI::App* cmd = app.add_subcommand(
      "render", "Render cameras of a reconstructed workspace (held-out views by default) and score them against the photos.");
  cmd->add_option("workspace", args->workspace, "Workspace folder")->required();
  using recon::ViewSplit;
  AddChoiceOption(cmd, "--split", &o.split, {{"test", ViewSplit::kTest}, {"train", ViewSplit::kTrain}, {"all", ViewSplit::kAll}},
                  "Which photos: test, train or all (all includes those left out for a wrong-looking pose)");
  cmd->add_option("--view", o.names, "Only this image (a scene.json name); repeatable");
  cmd->add_option("--checkpoint", args->checkpoint, "Checkpoint to render (default: the last level in WORKSPACE/recon)");
  cmd->add_option("-o,--out", args->out,
                  "Output folder (default: WORKSPACE/renders); a file already there is replaced only if it is a render "
                  "PERF wrote");
  AddMinBoxOpacityOption(cmd, &o.min_box_opacity, "Renders");
  cmd->add_flag("--opacity", o.write_opacity, "Also write <name>_opacity.png, the box opacity 1 - T (16-bit)");
  AddDeviceOptions(cmd, &o.device, &o.threads);
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  cmd->callback([args]() {
    recon::RenderViewsOptions& o = args->o;
    o.workspace = args->workspace;
    o.checkpoint = args->checkpoint;
    o.out_dir = args->out;
    // Renders into a folder of the user's (-o) are recorded in the workspace too, as PERF's: a
    // second render may replace them, and nothing else there.
    const std::unique_ptr<WorkspaceLock> lock = LockWorkspace(o.workspace, "render");
    Progress progress("render", args->quiet);
    o.progress = [&](int done, int total) { progress.Update(done, total, "views"); };
    const recon::RenderViewsResult r = recon::RenderViews(o);
    progress.Finish();
    if (args->quiet) return;
    std::cout << "rendered " << r.scores.size() << " views from " << r.checkpoint.string() << "\n";
    for (const recon::ViewScore& s : r.scores) std::cout << "  " << s.name << ": PSNR " << s.psnr << " dB\n";
    if (!r.scores.empty()) std::cout << "mean PSNR " << r.mean_psnr << " dB\n";
  });
}

}  // namespace perf
