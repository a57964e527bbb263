// Time to quality on the GPU (issue 4, paper figure 1): the hierarchy of perf reconstruct run
// with Gauss-Newton and with Adam on the same representation, data and device, recording the
// held-out PSNR against solver wall time, pass throughput against a roofline estimate, and peak
// GPU memory. Writes JSON and an SVG plot. Built to run on a bare GPU machine: it links no
// importer library (data from perf_bench_prep + bench/decode_images.py), the CUDA runtime and
// libstdc++ statically. Steps in bench/README.md.
//
//   perf_bench_gpu --data DIR [--solver both|gn|adam] [--levels 4] [--gn-iterations 10]
//                  [--adam-steps 200] [--adam-eval-every 20] [--out-dir bench/results] [--tag T]
//
// Solver wall time counts what perf reconstruct counts (building and uploading a level's rays,
// SetLevel, the solve, resampling); the held-out renders and the throughput probes are excluded.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>

#include "bench/svg_plot.h"
#include "common/errors.h"
#include "common/stopwatch.h"
#include "recon_cuda/cuda_backend.h"
#include "recon_cuda/evaluation.h"
#include "recon_cuda/render_rule.h"
#include "recon_cuda/solver.h"
#include "recon_cuda/training_data.h"
#include "recon_cuda/volume.h"

using namespace perf;
using namespace perf::recon;
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

struct View {
  std::string name;
  bool train = true;
  PinholeCamera<float> camera{};
  int width = 0, height = 0;
  const uint8_t* rgb = nullptr;    // [height, width, 3] in Data::pixels
  const uint8_t* alpha = nullptr;  // [height, width] in Data::alphas, or nullptr
};

// With alpha (every photo had one), the benchmark runs as perf reconstruct does by default:
// shells fixed at the background, the opacity residual fitting the alpha.
struct Data {
  VolumeGeometry geometry;
  float background[3] = {1, 1, 1};
  bool alpha = false;
  std::vector<View> views;
  std::vector<uint8_t> pixels;  // images.u8
  std::vector<uint8_t> alphas;  // alpha.u8
};

Data Load(const fs::path& dir) {
  const fs::path jpath = dir / "bench.json", upath = dir / "images.u8";
  std::ifstream jf(jpath);
  if (!jf) throw IoError(jpath.string(), "cannot read", "run perf_bench_prep (bench/README.md)");
  const json j = json::parse(jf);
  Data d;
  const json& p = j.at("placement");
  VolumePlacement pl;
  for (int a = 0; a < 3; ++a) {
    pl.box_center[a] = p.at("box_center").at(a);
    pl.box_size[a] = p.at("box_size").at(a);
    pl.shell_center[a] = p.at("shell_center").at(a);
  }
  for (int i = 0; i < 9; ++i) pl.box_rotation[i] = p.at("box_rotation").at(i);
  pl.shell_radii = p.at("shell_radii").get<std::vector<double>>();
  d.geometry = VolumeGeometry::From(pl, jpath.string());
  for (int c = 0; c < 3; ++c) d.background[c] = j.at("background").at(c);
  d.alpha = j.value("alpha", false);
  int64_t bytes = 0;
  for (const json& v : j.at("views")) {
    View w;
    w.name = v.at("name");
    w.train = v.at("split") == "train";
    w.width = v.at("width");
    w.height = v.at("height");
    w.camera.fx = v.at("fx");
    w.camera.fy = v.at("fy");
    w.camera.cx = v.at("cx");
    w.camera.cy = v.at("cy");
    for (int i = 0; i < 12; ++i) w.camera.world_from_cam[i] = v.at("world_from_cam").at(i);
    bytes += int64_t{3} * w.width * w.height;
    d.views.push_back(w);
  }
  std::ifstream uf(upath, std::ios::binary | std::ios::ate);
  if (!uf) throw IoError(upath.string(), "cannot read", "run python3 bench/decode_images.py on the data folder");
  if (static_cast<int64_t>(uf.tellg()) != bytes) {
    throw IoError(upath.string(), StrCat(uf.tellg(), " bytes, bench.json's views need ", bytes),
                  "re-run bench/decode_images.py");
  }
  d.pixels.resize(bytes);
  uf.seekg(0);
  uf.read(reinterpret_cast<char*>(d.pixels.data()), bytes);
  int64_t offset = 0;
  for (View& v : d.views) {
    v.rgb = d.pixels.data() + offset;
    offset += int64_t{3} * v.width * v.height;
  }
  if (d.alpha) {
    const fs::path apath = dir / "alpha.u8";
    std::ifstream af(apath, std::ios::binary | std::ios::ate);
    if (!af) throw IoError(apath.string(), "cannot read", "run python3 bench/decode_images.py on the data folder");
    if (static_cast<int64_t>(af.tellg()) != bytes / 3) {
      throw IoError(apath.string(), StrCat(af.tellg(), " bytes, bench.json's views need ", bytes / 3),
                    "re-run bench/decode_images.py");
    }
    d.alphas.resize(bytes / 3);
    af.seekg(0);
    af.read(reinterpret_cast<char*>(d.alphas.data()), bytes / 3);
    offset = 0;
    for (View& v : d.views) {
      v.alpha = d.alphas.data() + offset;
      offset += int64_t{v.width} * v.height;
    }
  }
  return d;
}

// The view as a float image, downscaled by an integer factor with a box filter (f x f pixel
// averages; perf reconstruct uses OpenImageIO's filtered resize, so its coarse levels see
// slightly smoother photos); intrinsics scaled as Downscaled (training_data.h) does.
// 8-bit pixels [height, width, channels] as floats in [0, 1], f x f pixel averages.
Image BoxDownscale(const uint8_t* bytes, int width, int height, int channels, int f) {
  const int w = std::max(1, width / f), h = std::max(1, height / f);
  Image out(w, h, channels);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < channels; ++c) {
        int sum = 0;
        for (int dy = 0; dy < f; ++dy)
          for (int dx = 0; dx < f; ++dx)
            sum += bytes[(static_cast<int64_t>(y * f + dy) * width + x * f + dx) * channels + c];
        out.at(x, y, c) = static_cast<float>(sum) / (255.f * f * f);
      }
    }
  }
  return out;
}

PosedImage ToPosed(const View& v, int f) {
  PosedImage p;
  p.name = v.name;
  p.camera = v.camera;
  p.image = BoxDownscale(v.rgb, v.width, v.height, 3, f);
  if (v.alpha) p.alpha = BoxDownscale(v.alpha, v.width, v.height, 1, f);
  const int w = p.image.width, h = p.image.height;
  const float sx = static_cast<float>(w) / v.width, sy = static_cast<float>(h) / v.height;
  p.camera.fx *= sx;
  p.camera.cx *= sx;
  p.camera.fy *= sy;
  p.camera.cy *= sy;
  return p;
}

struct Settings {
  int levels = 4, start = 32, gn_iterations = 10, adam_steps = 200, adam_eval_every = 20;
  uint32_t seed = 1;
  float min_box_opacity = kDefaultMinBoxOpacity;
  SolverOptions solver;  // GN settings and Adam's learning rates
};

struct Run {
  json points = json::array(), levels = json::array(), passes = json::object();
  std::vector<std::pair<double, double>> curve;  // (solver seconds, held-out PSNR)
  double seconds = 0, final_psnr = 0;
  int64_t peak_memory = 0;
};

double Elapsed(WallClock::time_point t0) { return SecondsSince(t0); }

// Throughput of one pass kind (best of 3), as rays/s and samples/s.
json MeasurePass(const std::function<PassStats()>& pass) {
  PassStats best;
  best.seconds = 1e30;
  for (int r = 0; r < 3; ++r) {
    const PassStats s = pass();
    if (s.seconds < best.seconds) best = s;
  }
  return {{"seconds", best.seconds},
          {"rays", best.rays},
          {"samples", best.samples},
          {"rays_per_s", best.rays / best.seconds},
          {"samples_per_s", best.samples / best.seconds}};
}

Run RunHierarchy(Backend* backend, const Data& d, SolverType type, const Settings& s) {
  Run run;
  std::vector<PinholeCamera<float>> train_cameras;
  std::vector<const View*> train, test;
  for (const View& v : d.views) {
    (v.train ? train : test).push_back(&v);
    if (v.train) train_cameras.push_back(v.camera);
  }
  std::vector<PosedImage> test_images;
  for (const View* v : test) test_images.push_back(ToPosed(*v, 1));
  const int num_shells = d.geometry.num_shells();
  std::vector<float> x;
  double elapsed = 0;
  int global_iteration = 0;
  for (int level = 0; level < s.levels; ++level) {
    const auto t_level = WallClock::now();
    double excluded = 0;  // held-out evaluation within this level
    const VolumeShape shape{s.start << level, s.start << level, num_shells};
    if (x.empty()) {
      x = InitialParams(shape, d.geometry, InitOptions{s.seed});
      if (d.alpha) SetBackgroundShells(shape, d.background, x);
    }
    const int factor = PyramidFactor(train_cameras, d.geometry, shape.n, 1 << (s.levels - 1 - level));
    std::vector<PosedImage> images;
    for (const View* v : train) images.push_back(ToPosed(*v, factor));
    const RaySet rays = MakeRaySet(images);
    images.clear();
    const MemoryEstimate mem = backend->SetLevel({shape, d.geometry, &rays, {}, d.alpha}, RequiredVectors(type));
    run.peak_memory = std::max(run.peak_memory, CudaMemoryInUse());
    SolverOptions so = s.solver;
    so.type = type;
    so.max_iterations = type == SolverType::kGaussNewton ? s.gn_iterations : s.adam_steps;
    so.seed = Hash(s.seed, static_cast<uint32_t>(level), 0x1e7e1u);
    auto held_out = [&] {
      const auto t0 = WallClock::now();
      const double psnr = MeanPsnr(ScoreViews(backend, kSolverX, test_images, s.min_box_opacity));
      run.peak_memory = std::max(run.peak_memory, CudaMemoryInUse());
      excluded += Elapsed(t0);
      return psnr;
    };
    auto callback = [&](const IterationSummary& it) {
      ++global_iteration;
      const bool last = it.iteration + 1 == so.max_iterations;
      const bool eval = type == SolverType::kGaussNewton || (it.iteration + 1) % s.adam_eval_every == 0 || last;
      if (!eval) return true;
      const double now = elapsed + Elapsed(t_level) - excluded;
      const double psnr = test_images.empty() ? 0 : held_out();
      run.points.push_back({{"level", level},
                            {"n", shape.n},
                            {"iteration", it.iteration},
                            {"elapsed_s", now},
                            {"test_psnr", psnr},
                            {"train_psnr", it.train_psnr},
                            {"cost", it.cost_after},
                            {"cg_iterations", it.cg_iterations},
                            {"step", it.step}});
      run.curve.push_back({now, psnr});
      std::printf("  %s level %d it %3d  %7.2f s  held-out %.2f dB  train %.2f dB\n", SolverName(type), level,
                  it.iteration + 1, now, psnr, it.train_psnr);
      std::fflush(stdout);
      return true;
    };
    SolverSummary summary;
    Solve(so, backend, &x, callback, &summary);
    if (summary.status == SolverStatus::kFailure) throw Error(StrCat("level ", level, ": ", summary.message));
    const double level_seconds = Elapsed(t_level) - excluded;
    elapsed += level_seconds;
    // Throughput at this level's solution (not counted as solver time). Vectors 1-3 are free
    // after Solve (x stays in kSolverX).
    json passes;
    passes["cost"] = MeasurePass([&] { return backend->Cost(kSolverX, 7); });
    if (type == SolverType::kGaussNewton) {
      passes["linearize"] = MeasurePass([&] { return backend->Linearize(kSolverX, 7, 1, 2); });
      passes["jtj_p"] = MeasurePass([&] { return backend->MultiplyJtJ(1, 3); });
    } else {
      passes["linearize_adam"] = MeasurePass([&] { return backend->Linearize(kSolverX, 7, 1, kNoVector); });
    }
    run.peak_memory = std::max(run.peak_memory, CudaMemoryInUse());
    run.levels.push_back({{"level", level},
                          {"n", shape.n},
                          {"m", shape.m},
                          {"params", shape.ParamCount()},
                          {"image_downscale", factor},
                          {"rays", rays.size()},
                          {"iterations", summary.iterations},
                          {"seconds", level_seconds},
                          {"seconds_linearize", summary.seconds_linearize},
                          {"seconds_cg", summary.seconds_cg},
                          {"seconds_line_search", summary.seconds_line_search},
                          {"seconds_update", summary.seconds_update},
                          {"seconds_psnr", summary.seconds_psnr},
                          {"passes", {{"linearize", summary.linearize_passes},
                                      {"jtj_p", summary.jtj_passes},
                                      {"cost", summary.cost_passes}}},
                          {"memory_estimate_bytes", mem.Total()},
                          {"throughput", passes},
                          {"report", summary.BriefReport()}});
    std::printf("%s level %d (%s, %lld rays, images / %d): %.2f s; %s\n", SolverName(type), level,
                DescribeShape(shape).c_str(), static_cast<long long>(rays.size()), factor, level_seconds,
                summary.BriefReport().c_str());
    run.passes[std::to_string(level)] = passes;
    if (level + 1 < s.levels) x = Resample(shape, x, shape.Doubled());
  }
  run.seconds = elapsed;
  run.final_psnr = run.curve.empty() ? 0 : run.curve.back().second;
  return run;
}

// First solver time at which the curve reaches `psnr` (-1: never).
double TimeTo(const std::vector<std::pair<double, double>>& curve, double psnr) {
  for (auto [t, p] : curve) {
    if (p >= psnr) return t;
  }
  return -1;
}

// Peak HBM bandwidth by device name (GB/s); 0 if unknown (then --bandwidth-gbs is needed).
double KnownBandwidth(const std::string& name) {
  if (name.find("H200") != std::string::npos) return 4800;
  if (name.find("H100") != std::string::npos) return name.find("PCIe") != std::string::npos ? 2000 : 3350;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"PERF GPU time to quality: GN vs Adam on the same hierarchy and device"};
  std::string data, solver = "both", out_dir = "bench/results", tag, commit = "unknown";
  Settings s;
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
  app.add_option("--seed", s.seed, "Random start and jitter")->capture_default_str();
  app.add_option("--min-box-opacity", s.min_box_opacity,
                 "Held-out renders: the paper's floater rule (0.7; 0: off, the volume as fitted)")
      ->check(CLI::Range(0.0f, 1.0f))
      ->capture_default_str();
  app.add_option("--bandwidth-gbs", bandwidth, "Peak memory bandwidth for the roofline (default: by device name)");
  app.add_option("--out-dir", out_dir, "Where the JSON and SVG go")->capture_default_str();
  app.add_option("--tag", tag, "File name stem (default: gpu_<data folder>_<date>)");
  app.add_option("--commit", commit, "Commit of the build, for the record")->capture_default_str();
  app.add_flag("--check-data", check_data, "Load the data, build every level's rays, print their sizes and exit (no GPU)");
  CLI11_PARSE(app, argc, argv);
  try {
    if (solver != "both" && solver != "gn" && solver != "adam") {
      throw InputError("command line", "--solver", solver, "unknown solver", "use both, gn or adam");
    }
    s.solver.adam.lr_opacity = s.solver.adam.lr_colour;
    s.solver.psnr_ray_stride = 0;  // the benchmark measures held-out PSNR itself
    const Data d = Load(data);
    if (check_data) {
      std::vector<PinholeCamera<float>> cams;
      std::vector<PosedImage> images;
      for (const View& v : d.views) {
        if (v.train) cams.push_back(v.camera);
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
    auto backend = MakeCudaBackend({});
    const std::string device = backend->Describe();
    int train = 0;
    for (const View& v : d.views) train += v.train;
    std::printf("%s; %d training and %zu held-out views; %d levels from %d^3\n", device.c_str(), train,
                d.views.size() - train, s.levels, s.start);
    std::map<std::string, Run> runs;
    for (SolverType t : {SolverType::kGaussNewton, SolverType::kAdam}) {
      if (solver != "both" && solver != SolverName(t)) continue;
      runs[SolverName(t)] = RunHierarchy(backend.get(), d, t, s);
    }

    json out{{"format", "perf-bench-gpu"},
             {"version", 1},
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
               {"min_box_opacity", s.min_box_opacity},
               {"seed", s.seed}}}};
    double best = 0;
    for (auto& [name, r] : runs)
      for (auto [t, p] : r.curve) best = std::max(best, p);
    for (auto& [name, r] : runs) {
      out["runs"][name] = {{"points", r.points},
                           {"levels", r.levels},
                           {"solver_seconds", r.seconds},
                           {"final_test_psnr", r.final_psnr},
                           {"peak_gpu_memory_bytes", r.peak_memory},
                           {"time_to_30db_s", TimeTo(r.curve, 30.0)},
                           {"time_to_95pct_of_best_s", TimeTo(r.curve, 0.95 * best)}};
      std::printf("%s: %.2f s, final held-out %.2f dB, 30 dB at %.2f s, 95 %% of best (%.2f dB) at %.2f s, peak GPU "
                  "memory %.2f GiB\n",
                  name.c_str(), r.seconds, r.final_psnr, TimeTo(r.curve, 30.0), 0.95 * best,
                  TimeTo(r.curve, 0.95 * best), r.peak_memory / 1073741824.0);
    }
    out["best_test_psnr"] = best;
    if (runs.count("gn") && runs.count("adam")) {
      const double g = TimeTo(runs["gn"].curve, 0.95 * best), a = TimeTo(runs["adam"].curve, 0.95 * best);
      out["adam_over_gn_time_to_95pct"] = g > 0 && a > 0 ? json(a / g) : json(nullptr);
    }

    // Roofline of the march (the cost pass: forward only). A sample gathers 8 cells of 4 floats:
    // 128 B if nothing were reused; consecutive samples of a ray share about half their cells
    // (a step is one cell side), so ~64 B of new cells per sample; L2 reuse across neighbouring
    // rays (8 x 8 pixel tiles per block) lowers the DRAM traffic further, so these are upper
    // bounds of a bandwidth-bound kernel. samples/s <= B / b.
    if (bandwidth <= 0) bandwidth = KnownBandwidth(device);
    const Run& any = runs.count("gn") ? runs["gn"] : runs.begin()->second;
    const json last_cost = any.passes[std::to_string(s.levels - 1)]["cost"];
    const double measured = last_cost["samples_per_s"];
    json roof{{"bandwidth_gbs", bandwidth},
              {"bytes_per_sample_no_reuse", 128},
              {"bytes_per_sample_ray_reuse", 64},
              {"measured_cost_pass_samples_per_s", measured}};
    if (bandwidth > 0) {
      const double b128 = bandwidth * 1e9 / 128, b64 = bandwidth * 1e9 / 64;
      roof["bound_no_reuse_samples_per_s"] = b128;
      roof["bound_ray_reuse_samples_per_s"] = b64;
      std::printf("roofline (march, last level): measured %.3g samples/s; bandwidth bound %.3g (128 B/sample) to "
                  "%.3g (64 B/sample) at %.0f GB/s: %.0f %% / %.0f %%\n",
                  measured, b128, b64, bandwidth, 100 * measured / b128, 100 * measured / b64);
    }
    out["roofline"] = roof;

    fs::create_directories(out_dir);
    if (tag.empty()) {
      char date[32];
      const std::time_t now = std::time(nullptr);
      std::strftime(date, sizeof(date), "%Y%m%d_%H%M%S", std::gmtime(&now));
      tag = StrCat("gpu_", fs::path(data).filename().string(), "_", date);
    }
    const fs::path json_path = fs::path(out_dir) / (tag + ".json"), svg_path = fs::path(out_dir) / (tag + ".svg");
    std::ofstream(json_path) << out.dump(1) << "\n";
    std::vector<bench::Series> series;
    if (runs.count("gn")) series.push_back({"Gauss-Newton", "#d62728", runs["gn"].curve});
    if (runs.count("adam")) series.push_back({"Adam", "#1f77b4", runs["adam"].curve});
    std::ofstream(svg_path) << bench::LinePlotSvg(series, StrCat("held-out PSNR vs solver time, ", device),
                                                  "solver wall time (s)", "held-out PSNR (dB)");
    std::printf("wrote %s and %s\n", json_path.c_str(), svg_path.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
