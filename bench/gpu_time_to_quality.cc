// Time to quality on the GPU (paper figure 1): the hierarchy of perf reconstruct run
// with Gauss-Newton and with Adam on the same representation, data and device, recording the
// held-out PSNR against solver wall time, pass throughput against a roofline estimate, and peak
// GPU memory. Writes JSON and an SVG plot after every evaluation and every level (atomically:
// a run killed by a time limit leaves the figures so far). Built to run on a bare GPU machine:
// it links no importer library (data from perf_bench_prep + bench/decode_images.py), the CUDA
// runtime and libstdc++ statically. Steps in bench/README.md; the engine is time_to_quality.h.
//
//   perf_bench_gpu --data DIR [--solver both|gn|adam] [--levels 4] [--gn-iterations 10]
//                  [--adam-steps 200] [--adam-eval-every 20] [--time-budget S]
//                  [--out-dir bench/results] [--tag T]
//
// Solver wall time counts what perf reconstruct counts (building and uploading a level's rays,
// SetLevel, the solve, resampling); the held-out renders and the throughput probes are excluded.
// --time-budget S (and SIGTERM / SIGINT) end the run at the next solver iteration, after which
// the results so far are written; with --solver both, Gauss-Newton may use the first half of the
// budget and Adam the rest.
#include <CLI/CLI.hpp>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>

#include "bench/time_to_quality.h"
#include "common/errors.h"
#include "common/stopwatch.h"
#include "recon_cuda/backends/cuda_backend.h"
#include "recon_cuda/data/training_data.h"

using namespace perf;
using namespace perf::recon;
using namespace perf::bench;
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

std::atomic<bool> g_stop{false};
extern "C" void OnStopSignal(int) { g_stop.store(true); }

// --check-data: every level's rays built from the data, their sizes and means printed (no GPU).
int CheckData(const BenchData& d, const BenchSettings& s) {
  std::vector<ViewFrustum> cams;
  std::vector<PosedImage> images;
  for (const View& v : d.views) {
    if (v.train) cams.push_back({v.camera, v.width, v.height});
  }
  for (int level = 0; level < s.levels; ++level) {
    const int n = s.start << level, f = PyramidFactor(cams, d.geometry, n, 1 << (s.levels - 1 - level));
    images.clear();
    double sum = 0;
    for (const View& v : d.views) {
      if (v.train) images.push_back(ToPosed(v, f));
    }
    const RaySet rays = MakeRaySet(images);
    for (float c : rays.colours) sum += c;
    double alpha_sum = 0;
    for (float a : rays.alphas) alpha_sum += a;
    std::printf("level %d: %d^3, images / %d, %lld rays, mean colour %.4f, mean alpha %s\n", level, n, f,
                static_cast<long long>(rays.size()), sum / std::max<size_t>(1, rays.colours.size()),
                rays.alphas.empty() ? "(none)" : StrCat(alpha_sum / rays.alphas.size()).c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"PERF GPU time to quality: GN vs Adam on the same hierarchy and device"};
  std::string data, solver = "both", out_dir = "bench/results", tag, commit = "unknown";
  BenchSettings s;
  double time_budget = 0;
  double bandwidth = 0;
  bool check_data = false;
  app.add_option("--data", data, "Folder from perf_bench_prep + decode_images.py")->required();
  app.add_option("--solver", solver, "both, gn or adam")->capture_default_str();
  app.add_option("--levels", s.levels, "Hierarchy levels from --start-resolution")->capture_default_str();
  app.add_option("--start-resolution", s.start, "Grid cells per axis at level 1")->capture_default_str();
  app.add_option("--gn-iterations", s.gn_iterations, "Gauss-Newton iterations per level")->capture_default_str();
  app.add_option("--adam-steps", s.adam_steps, "Adam steps per level")->capture_default_str();
  app.add_option("--adam-eval-every", s.adam_eval_every, "Held-out PSNR every K Adam steps")->capture_default_str();
  app.add_option("--lr-colour", s.solver.adam.lr_colour, "Adam learning rate of colours and opacities")
      ->capture_default_str();
  app.add_option("--lr-density", s.solver.adam.lr_density, "Adam learning rate of densities")->capture_default_str();
  app.add_option("--max-cg-iterations", s.solver.max_cg_iterations, "PCG iterations per GN step")
      ->capture_default_str();
  app.add_option("--line-search-stride", s.solver.line_search_ray_stride, "Line search on every k-th ray")
      ->capture_default_str();
  app.add_option("--cg-exit-ratio", s.solver.cg_exit_ratio,
                 "PCG leaves when |r|^2 falls by less than this factor (paper: 0.85; default inf: never)")
      ->check(CLI::PositiveNumber);
  app.add_option("--jtj-ray-stride", s.solver.jtj_ray_stride,
                 "PCG's J^T J p on every k-th ray (subsampled Gauss-Newton; 1: every ray)")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_option("--seed", s.seed, "Random start and jitter")->capture_default_str();
  app.add_option("--min-box-opacity", s.min_box_opacity,
                 "Held-out renders: the paper's floater rule (0.7; 0: off, the volume as fitted)")
      ->check(CLI::Range(0.0f, 1.0f))
      ->capture_default_str();
  app.add_option("--bandwidth-gbs", bandwidth, "Peak memory bandwidth for the roofline (default: by device name)");
  app.add_option("--time-budget", time_budget,
                 "Wall seconds for the whole run (0: none); it stops at the next solver iteration after it and "
                 "writes what it has (with --solver both: GN the first half, Adam the rest)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--out-dir", out_dir, "Where the JSON and SVG go (rewritten after every evaluation)")
      ->capture_default_str();
  app.add_option("--tag", tag, "File name stem (default: gpu_<data folder>_<date>)");
  app.add_option("--commit", commit, "Commit of the build, for the record")->capture_default_str();
  bool dense = false, no_record = false;
  app.add_flag("--dense", dense, "Every level's grid dense (default: levels after the first keep the occupied bricks)");
  app.add_flag("--no-record", no_record,
               "J^T J p recomputes every ray (default: it reads the Jacobian record Linearize wrote, ray_record.h)");
  app.add_flag("--check-data", check_data, "Load the data, build every level's rays, print their sizes and exit (no GPU)");
  CLI11_PARSE(app, argc, argv);
  try {
    if (solver != "both" && solver != "gn" && solver != "adam") {
      throw InputError("command line", "--solver", solver, "unknown solver", "use both, gn or adam");
    }
    s.solver.adam.lr_opacity = s.solver.adam.lr_colour;
    s.sparse = !dense;
    s.solver.psnr_ray_stride = 0;  // the benchmark measures held-out PSNR itself
    const auto t_start = WallClock::now();
    const BenchData d = LoadBenchData(data);
    if (check_data) return CheckData(d, s);
    std::signal(SIGTERM, OnStopSignal);
    std::signal(SIGINT, OnStopSignal);
    CudaBackendOptions cuda_options;
    cuda_options.record_jacobian = !no_record;
    auto backend = MakeCudaBackend(cuda_options);
    const std::string device = backend->Describe();
    int train = 0;
    for (const View& v : d.views) train += v.train;
    std::printf("%s; %d training and %zu held-out views; %d levels from %d^3\n", device.c_str(), train,
                d.views.size() - train, s.levels, s.start);
    if (bandwidth <= 0) bandwidth = KnownBandwidth(device);
    if (tag.empty()) {
      char date[32];
      const std::time_t now = std::time(nullptr);
      std::strftime(date, sizeof(date), "%Y%m%d_%H%M%S", std::gmtime(&now));
      tag = StrCat("gpu_", fs::path(data).filename().string(), "_", date);
    }
    const ResultsFiles files(out_dir, tag);
    const json header{{"format", "perf-bench-gpu"},
                      {"version", 2},
                      {"device", device},
                      {"commit", commit},
                      {"data", fs::absolute(data).string()},
                      {"train_views", train},
                      {"test_views", static_cast<int>(d.views.size()) - train},
                      {"settings",
                       {{"levels", s.levels},
                        {"start_resolution", s.start},
                        {"gn_iterations_per_level", s.gn_iterations},
                        {"adam_steps_per_level", s.adam_steps},
                        {"adam_eval_every", s.adam_eval_every},
                        {"lr_colour", s.solver.adam.lr_colour},
                        {"lr_density", s.solver.adam.lr_density},
                        {"max_cg_iterations", s.solver.max_cg_iterations},
                        {"line_search_ray_stride", s.solver.line_search_ray_stride},
                        {"cg_exit_ratio", std::isfinite(s.solver.cg_exit_ratio) ? json(s.solver.cg_exit_ratio) : json()},
                        {"jtj_ray_stride", s.solver.jtj_ray_stride},
                        {"min_box_opacity", s.min_box_opacity},
                        {"sparse", s.sparse},
                        {"record_jacobian", !no_record},
                        {"time_budget_s", time_budget},
                        {"seed", s.seed}}}};
    std::map<std::string, SolverRun> runs;
    std::vector<SolverType> types;
    for (SolverType t : {SolverType::kGaussNewton, SolverType::kAdam}) {
      if (solver == "both" || solver == SolverName(t)) types.push_back(t);
    }
    RunContext ctx;
    ctx.clock = [t_start] { return SecondsSince(t_start); };
    ctx.stop = &g_stop;
    ctx.memory_in_use = CudaMemoryInUse;
    for (size_t k = 0; k < types.size(); ++k) {
      const std::string name = SolverName(types[k]);
      // The budget's share of solvers 0..k (with both: GN until half of it, Adam until the end).
      if (time_budget > 0) ctx.deadline = time_budget * static_cast<double>(k + 1) / types.size();
      ctx.on_update = [&](const SolverRun& r) {
        runs[name] = r;
        files.Write(header, runs, bandwidth, device);
      };
      SolverRun run;
      RunHierarchy(backend.get(), d, types[k], s, ctx, &run);
      runs[name] = run;
      files.Write(header, runs, bandwidth, device);
      if (g_stop.load()) break;
    }
    const json out = ResultsJson(header, runs, bandwidth);
    const double best = out["best_test_psnr"];
    for (auto& [name, r] : runs) {
      std::printf("%s: %.2f s%s, final held-out %.2f dB, 30 dB at %.2f s, 95 %% of best (%.2f dB) at %.2f s, peak "
                  "GPU memory %.2f GiB\n",
                  name.c_str(), r.seconds, r.stopped.empty() ? "" : StrCat(" (stopped: ", r.stopped, ")").c_str(),
                  r.final_psnr, TimeTo(r.curve, 30.0), 0.95 * best, TimeTo(r.curve, 0.95 * best),
                  r.peak_memory / 1073741824.0);
    }
    if (out.contains("roofline") && bandwidth > 0) {
      const json& roof = out["roofline"];
      const double measured = roof["measured_cost_pass_samples_per_s"], b128 = roof["bound_no_reuse_samples_per_s"],
                   b64 = roof["bound_ray_reuse_samples_per_s"];
      std::printf("roofline (march, level %d): measured %.3g samples/s; bandwidth bound %.3g (128 B/sample) to "
                  "%.3g (64 B/sample) at %.0f GB/s: %.0f %% / %.0f %%\n",
                  roof["level"].get<int>(), measured, b128, b64, bandwidth, 100 * measured / b128,
                  100 * measured / b64);
    }
    std::printf("wrote %s and %s\n", files.json_path.c_str(), files.svg_path.c_str());
    if (g_stop.load()) return 128 + SIGTERM;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
