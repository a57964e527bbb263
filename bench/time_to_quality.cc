#include "bench/time_to_quality.h"

#include <algorithm>
#include <cstdio>
#include <fstream>

#include "bench/svg_plot.h"
#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/stopwatch.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/data/volume.h"
#include "recon_cuda/run/evaluation.h"
#include "recon_cuda/solve/hierarchy.h"

namespace perf::bench {
namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace perf::recon;

BenchData LoadBenchData(const fs::path& dir) {
  const fs::path jpath = dir / "bench.json", upath = dir / "images.u8";
  std::ifstream jf(jpath);
  if (!jf) throw IoError(jpath.string(), "cannot read", "run perf_bench_prep (bench/README.md)");
  const json j = json::parse(jf);
  BenchData d;
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

namespace {

// 8-bit pixels [height, width, channels] as floats in [0, 1], f x f pixel averages (perf
// reconstruct uses OpenImageIO's filtered resize, so its coarse levels see slightly smoother
// photos).
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

}  // namespace

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

void RunHierarchy(Backend* backend, const BenchData& d, SolverType type, const BenchSettings& s,
                  const RunContext& ctx, SolverRun* run) {
  const auto clock = ctx.clock ? ctx.clock : [t0 = WallClock::now()] { return SecondsSince(t0); };
  auto peak = [&] {
    if (ctx.memory_in_use) run->peak_memory = std::max(run->peak_memory, ctx.memory_in_use());
  };
  auto update = [&] {
    if (ctx.on_update) ctx.on_update(*run);
  };
  // Why the run must end now ("" if it need not).
  auto stop_reason = [&]() -> std::string {
    if (ctx.stop && ctx.stop->load()) return "signal";
    if (clock() > ctx.deadline) return "time budget";
    return "";
  };
  std::vector<const View*> train, test;
  for (const View& v : d.views) (v.train ? train : test).push_back(&v);
  std::vector<PosedImage> test_images;
  for (const View* v : test) test_images.push_back(ToPosed(*v, 1));

  // The hierarchy of perf reconstruct (recon_cuda/solve/hierarchy.h) with its default residuals and,
  // with alpha, the shells fixed at the background.
  HierarchyOptions ho;
  ho.levels = s.levels;
  ho.start_resolution = s.start;
  ho.solver = s.solver;
  ho.solver.type = type;
  ho.iterations = type == SolverType::kGaussNewton ? s.gn_iterations : s.adam_steps;
  ho.init = InitOptions{s.seed};
  ho.sparse = s.sparse;
  ho.fixed_background = d.alpha;
  ho.background = {d.background[0], d.background[1], d.background[2]};
  TrainingViews views;
  for (const View* v : train) views.views.push_back({v->camera, v->width, v->height});
  views.rays = [&](int factor) {
    std::vector<PosedImage> images;
    for (const View* v : train) images.push_back(ToPosed(*v, factor));
    return MakeRaySet(images);
  };

  double elapsed = 0, t_level = 0, excluded = 0;  // excluded: held-out evaluation within the level
  std::string stopped;
  HierarchyCallbacks cb;
  cb.before_level = [&](int) {
    stopped = stop_reason();
    if (!stopped.empty()) {
      run->stopped = stopped;
      update();
    }
    t_level = clock();
    excluded = 0;
    return stopped.empty();
  };
  cb.level_started = [&](const HierarchyLevel&) { peak(); };
  cb.iteration = [&](const HierarchyLevel& h, const IterationSummary& it) {
    const bool last = it.iteration + 1 == h.solver.max_iterations;
    stopped = stop_reason();
    const bool eval = type == SolverType::kGaussNewton || (it.iteration + 1) % s.adam_eval_every == 0 || last ||
                      !stopped.empty();
    if (eval) {
      const double now = elapsed + clock() - t_level - excluded;
      double psnr = 0;
      if (!test_images.empty()) {
        const double t0 = clock();
        psnr = MeanPsnr(ScoreViews(backend, h.params, test_images, s.min_box_opacity));
        peak();
        excluded += clock() - t0;
      }
      run->points.push_back({{"level", h.level},
                             {"n", h.shape.n},
                             {"iteration", it.iteration},
                             {"elapsed_s", now},
                             {"test_psnr", psnr},
                             {"train_psnr", it.train_psnr},
                             {"cost", it.cost_after},
                             {"cg_iterations", it.cg_iterations},
                             {"step", it.step}});
      run->curve.push_back({now, psnr});
      run->final_psnr = psnr;
      run->seconds = now;
      std::printf("  %s level %d it %3d  %7.2f s  held-out %.2f dB  train %.2f dB\n", SolverName(type), h.level,
                  it.iteration + 1, now, psnr, it.train_psnr);
      std::fflush(stdout);
      update();
    }
    return stopped.empty();
  };
  cb.level_done = [&](const HierarchyLevel& h, const SolverSummary& summary, const std::vector<float>&) {
    const double level_seconds = clock() - t_level - excluded;
    elapsed += level_seconds;
    run->seconds = elapsed;
    // Throughput at this level's solution (not counted as solver time; skipped when the run is
    // stopping), in the solver's scratch vectors.
    json passes = json::object();
    if (stopped.empty()) {
      const std::vector<VecId> scratch = VectorsOf(type).scratch;
      const VecId a = scratch.at(0), b = scratch.at(1), c = scratch.at(2);
      passes["cost"] = MeasurePass([&] { return backend->Cost(h.params, 7); });
      if (type == SolverType::kGaussNewton) {
        passes["linearize"] = MeasurePass([&] { return backend->Linearize(h.params, 7, a, b); });
        passes["jtj_p"] = MeasurePass([&] { return backend->MultiplyJtJ(a, c); });
      } else {
        passes["linearize_adam"] = MeasurePass([&] { return backend->Linearize(h.params, 7, a, kNoVector); });
      }
      run->passes[std::to_string(h.level)] = passes;
    }
    peak();
    json entry{{"level", h.level},
               {"n", h.shape.n},
               {"bricks", h.shape.StoredBricks()},
               {"bricks_of", BrickCount(h.shape.n)},
               {"m", h.shape.m},
               {"params", h.shape.ParamCount()},
               {"image_downscale", h.image_downscale},
               {"rays", h.rays},
               {"iterations", summary.iterations},
               {"seconds", level_seconds},
               {"solver", summary.ToJson()},
               {"memory_estimate_bytes", h.memory.Total()},
               {"jacobian_record_bytes", h.memory.jacobian_cache},
               {"jacobian_record_wanted_bytes", h.memory.jacobian_wanted},
               {"throughput", passes}};
    if (!stopped.empty()) entry["stopped"] = stopped;
    run->levels.push_back(entry);
    std::printf("%s level %d (%s, %lld rays, images / %d): %.2f s; %s%s\n", SolverName(type), h.level,
                DescribeShape(h.shape).c_str(), static_cast<long long>(h.rays), h.image_downscale, level_seconds,
                summary.BriefReport().c_str(), stopped.empty() ? "" : StrCat("; stopped: ", stopped).c_str());
    std::fflush(stdout);
    if (!stopped.empty()) run->stopped = stopped;
    run->complete = stopped.empty() && h.level + 1 == s.levels;
    update();
  };
  SolveHierarchy(backend, d.geometry, views, ho, HierarchyStart{}, cb);
  run->final_psnr = run->curve.empty() ? 0 : run->curve.back().second;
}

double TimeTo(const std::vector<std::pair<double, double>>& curve, double psnr) {
  for (auto [t, p] : curve) {
    if (p >= psnr) return t;
  }
  return -1;
}

double KnownBandwidth(const std::string& name) {
  if (name.find("H200") != std::string::npos) return 4800;
  if (name.find("H100") != std::string::npos) return name.find("PCIe") != std::string::npos ? 2000 : 3350;
  return 0;
}

json ResultsJson(const json& header, const std::map<std::string, SolverRun>& runs, double bandwidth) {
  json out = header;
  double best = 0;
  for (auto& [name, r] : runs)
    for (auto [t, p] : r.curve) best = std::max(best, p);
  out["runs"] = json::object();
  for (auto& [name, r] : runs) {
    out["runs"][name] = {{"points", r.points},
                         {"levels", r.levels},
                         {"complete", r.complete},
                         {"stopped", r.stopped.empty() ? json(nullptr) : json(r.stopped)},
                         {"solver_seconds", r.seconds},
                         {"final_test_psnr", r.final_psnr},
                         {"peak_gpu_memory_bytes", r.peak_memory},
                         {"time_to_30db_s", TimeTo(r.curve, 30.0)},
                         {"time_to_95pct_of_best_s", TimeTo(r.curve, 0.95 * best)}};
  }
  out["best_test_psnr"] = best;
  if (runs.count("gn") && runs.count("adam")) {
    const double g = TimeTo(runs.at("gn").curve, 0.95 * best), a = TimeTo(runs.at("adam").curve, 0.95 * best);
    out["adam_over_gn_time_to_95pct"] = g > 0 && a > 0 ? json(a / g) : json(nullptr);
  }
  // Roofline of the march (the cost pass: forward only), at the last level whose passes were
  // timed. A sample gathers 8 cells of 4 floats: 128 B if nothing were reused; consecutive
  // samples of a ray share about half their cells (a step is one cell side), so ~64 B of new
  // cells per sample; L2 reuse across neighbouring rays lowers the DRAM traffic further, so these
  // are upper bounds of a bandwidth-bound kernel. samples/s <= B / b.
  const SolverRun* timed = nullptr;
  if (runs.count("gn")) timed = &runs.at("gn");
  if ((!timed || timed->passes.empty()) && runs.count("adam")) timed = &runs.at("adam");
  if (timed && !timed->passes.empty()) {
    int last = -1;
    for (auto& [level, p] : timed->passes.items()) last = std::max(last, std::stoi(level));
    const double measured = timed->passes[std::to_string(last)]["cost"]["samples_per_s"];
    json roof{{"level", last},
              {"bandwidth_gbs", bandwidth},
              {"bytes_per_sample_no_reuse", 128},
              {"bytes_per_sample_ray_reuse", 64},
              {"measured_cost_pass_samples_per_s", measured}};
    if (bandwidth > 0) {
      roof["bound_no_reuse_samples_per_s"] = bandwidth * 1e9 / 128;
      roof["bound_ray_reuse_samples_per_s"] = bandwidth * 1e9 / 64;
    }
    out["roofline"] = roof;
  }
  return out;
}

std::string ResultsSvg(const std::map<std::string, SolverRun>& runs, const std::string& device) {
  std::vector<Series> series;
  if (runs.count("gn")) series.push_back({"Gauss-Newton", "#d62728", runs.at("gn").curve});
  if (runs.count("adam")) series.push_back({"Adam", "#1f77b4", runs.at("adam").curve});
  return LinePlotSvg(series, StrCat("held-out PSNR vs solver time, ", device), "solver wall time (s)",
                     "held-out PSNR (dB)");
}

ResultsFiles::ResultsFiles(const fs::path& dir, const std::string& tag)
    : json_path(dir / (tag + ".json")), svg_path(dir / (tag + ".svg")) {
  EnsureWritableDirectory(dir);
}

void ResultsFiles::Write(const nlohmann::json& header, const std::map<std::string, SolverRun>& runs,
                         double bandwidth, const std::string& device) const {
  WriteFileAtomically(json_path, ResultsJson(header, runs, bandwidth).dump(1) + "\n");
  WriteFileAtomically(svg_path, ResultsSvg(runs, device));
}

}  // namespace perf::bench
