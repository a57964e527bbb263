// Throughput of the solver's passes on the CPU backend: rays/s and samples/s of Linearize (cost,
// J^T r, diag, recorded Jacobian), MultiplyJtJ, the cost-only pass, Linearize as Adam runs it
// (no diagonal, nothing recorded), and MultiplyJtJ as Gauss-Newton's CG runs it: restricted to
// the free parameters (HoldParameters, RestrictJacobian), where it visits fewer samples. With the
// merged record (the default at degree 0; --sample-record for the samples) J^T J p's "samples"
// are the rays' cells, about 4 a sample.
//
//   perf_bench_cpu --workspace WS [--checkpoint FILE] [--n 64] [--threads 2] [--repeat 3]
//   perf_bench_cpu --workspace WS --levels 2 [--start-resolution 32] [--iterations 10] [--modes both]
//     (the hierarchy sparse and dense side by side: bench/cpu_hierarchy.h)
//
// WS is a workspace made by perf import (e.g. lego --downscale 16); the volume is the checkpoint
// (resampled to --n) when given, else the random start. Prints one line per pass and, with
// --json FILE, writes the figures as JSON.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "bench/cpu_hierarchy.h"
#include "common/errors.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/solve/solver.h"

using namespace perf;
using namespace perf::recon;

int main(int argc, char** argv) {
  CLI::App app{"PERF CPU pass throughput"};
  std::string workspace, checkpoint, json_path;
  int n = 64, threads = 0, repeat = 3;
  app.add_option("--workspace", workspace, "Workspace made by perf import")->required();
  app.add_option("--checkpoint", checkpoint, "Volume to evaluate (default: the random start)");
  app.add_option("--n", n, "Grid resolution (the checkpoint is resampled to it)")->capture_default_str();
  app.add_option("--threads", threads, "Worker threads (0: all cores)")->capture_default_str();
  app.add_option("--repeat", repeat, "Runs per pass (the best is reported)")->capture_default_str();
  app.add_option("--json", json_path, "Also write the figures here");
  bool as_dense = false;
  std::string only;
  app.add_option("--only", only,
                 "Time one pass alone, for back-to-back comparisons: cost, or jtjp (after one Linearize)")
      ->check(CLI::IsMember({"cost", "jtjp"}));
  app.add_flag("--as-dense", as_dense, "A sparse checkpoint's volume in the dense layout (the same values)");
  bool exact_record = false;
  app.add_flag("--exact-record", exact_record,
               "Record the Jacobian exactly (floats, absolute positions) instead of compactly (the default)");
  bool sample_record = false;
  app.add_flag("--sample-record", sample_record,
               "Record the compact Jacobian sample by sample instead of each ray's cells merged (the default)");
  bench::CpuHierarchySettings hs;
  std::string modes = "both";
  app.add_option("--levels", hs.levels,
                 "Run perf reconstruct's hierarchy with this many levels instead, sparse and dense side by side "
                 "(0: the pass throughput only)")
      ->default_val(0);
  app.add_option("--start-resolution", hs.start, "Hierarchy: grid cells per axis at level 1")->capture_default_str();
  app.add_option("--iterations", hs.iterations, "Hierarchy: GN iterations a level")->capture_default_str();
  app.add_option("--min-occupancy", hs.occupancy.min_opacity, "Hierarchy: occupied cell opacity (occupancy.h)")
      ->capture_default_str();
  app.add_option("--dilation", hs.occupancy.dilation, "Hierarchy: occupied cells grow by this many cells")
      ->capture_default_str();
  app.add_option("--modes", modes, "Hierarchy: both, sparse or dense")->check(CLI::IsMember({"both", "sparse", "dense"}))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    if (hs.levels > 0) {
      hs.workspace = workspace;
      hs.threads = threads;
      hs.sparse = modes != "dense";
      hs.dense = modes != "sparse";
      const nlohmann::json out = bench::RunCpuHierarchy(hs);
      if (!json_path.empty()) std::ofstream(json_path) << out.dump(2) << "\n";
      return 0;
    }
    const Scene scene = ReadScene(std::filesystem::path(workspace) / "scene.json");
    const VolumeGeometry geometry = VolumeGeometry::FromScene(scene);
    const RaySet rays = MakeRaySet(LoadImages(scene, workspace, Split::kTrain));
    VolumeShape shape{n, n, geometry.num_shells()};
    std::vector<float> x;
    if (!checkpoint.empty()) {
      const Checkpoint c = ReadCheckpoint(checkpoint);
      if (c.shape.n == n && !as_dense) {
        shape = c.shape;  // as stored (a sparse checkpoint stays sparse, its shells keep their size)
        x = c.params;
      } else {
        if (c.shape.n == n) shape.m = c.shape.m;  // --as-dense: only the grid's layout changes
        x = Resample(c.shape, c.params, shape);
      }
    } else {
      x = InitialParams(shape, geometry, InitOptions{});
    }
    CpuBackendOptions o;
    o.threads = threads;
    o.compact_jacobian = !exact_record;
    o.merged_jacobian = !exact_record && !sample_record;
    auto backend = MakeCpuBackend(o);
    LevelProblem problem{shape, geometry, &rays, {}};
    problem.start = x;  // as the hierarchy plans a level
    backend->SetLevel(problem, 5);
    backend->Upload(0, x);
    std::printf("%s, %s, %lld rays, Jacobian cache %s\n", backend->Describe().c_str(), DescribeShape(shape).c_str(),
                static_cast<long long>(rays.size()), backend->CachesJacobian() ? "on" : "off");
    nlohmann::json out{{"backend", backend->Describe()}, {"n", n}, {"rays", rays.size()}};
    auto measure = [&](const char* name, auto&& pass) {
      PassStats best;
      best.seconds = 1e30;
      for (int r = 0; r < repeat; ++r) {
        const PassStats s = pass();
        if (s.seconds < best.seconds) best = s;
      }
      const double rps = best.rays / best.seconds, sps = best.samples / best.seconds;
      std::printf("  %-22s %8.3f s  %7.2f M rays/s  %7.1f M samples/s  (%.1f samples/ray)\n", name, best.seconds,
                  rps / 1e6, sps / 1e6, static_cast<double>(best.samples) / std::max<int64_t>(1, best.rays));
      out["passes"][name] = {{"seconds", best.seconds}, {"rays_per_s", rps}, {"samples_per_s", sps}};
    };
    if (only == "cost") {
      measure("cost", [&] { return backend->Cost(0, 7); });
    } else if (only == "jtjp") {
      const PassStats first = backend->Linearize(0, 7, 1, 2);  // its record's pages are touched first
      std::printf("  %-22s %8.3f s  (the record's first touch)\n", "linearize (first)", first.seconds);
      measure("J^T J p", [&] { return backend->MultiplyJtJ(1, 3); });
    } else {
      measure("linearize (GN)", [&] { return backend->Linearize(0, 7, 1, 2); });
      measure("J^T J p", [&] { return backend->MultiplyJtJ(1, 3); });
      measure("cost", [&] { return backend->Cost(0, 7); });
      measure("linearize (Adam)", [&] { return backend->Linearize(0, 7, 1, kNoVector); });
      backend->Linearize(0, 7, 1, 2);
      backend->HoldParameters(0, 1, 4, true);
      backend->RestrictJacobian(4);
      const double held = static_cast<double>(shape.ParamCount()) - backend->Dot(4, 4);
      std::printf("  %.1f %% of the parameters held; J^T J p on the free ones visits only these samples:\n",
                  100.0 * held / shape.ParamCount());
      measure("J^T J p (free set)", [&] { return backend->MultiplyJtJ(1, 3); });
    }
    if (!json_path.empty()) std::ofstream(json_path) << out.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
