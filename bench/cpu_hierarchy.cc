#include "bench/cpu_hierarchy.h"

#include <cstdio>
#include <filesystem>

#include "common/errors.h"
#include "common/stopwatch.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/run/evaluation.h"
#include "recon_cuda/run/reconstruct.h"
#include "workspace/scene.h"

namespace perf::bench {

using namespace perf::recon;
using nlohmann::json;

namespace {

// Seconds per pass of the level's solve (0 where it ran none).
double PerPass(double seconds, int passes) { return passes > 0 ? seconds / passes : 0.0; }

json RunMode(const CpuHierarchySettings& s, bool sparse, const Scene& scene, const std::vector<PosedImage>& train,
             const std::vector<PosedImage>& test) {
  const VolumeGeometry geometry = VolumeGeometry::FromScene(scene);
  CpuBackendOptions bo;
  bo.threads = s.threads;
  const std::unique_ptr<Backend> backend = MakeCpuBackend(bo);
  HierarchyOptions ho;
  ho.levels = s.levels;
  ho.start_resolution = s.start;
  ho.iterations = s.iterations;
  ho.sparse = sparse;
  ho.occupancy = s.occupancy;
  SetHierarchyBackground(BackgroundChoice::kAuto, scene, &ho);  // as perf reconstruct does by default
  const TrainingViews views = ViewsForHierarchy(train);
  const char* mode = sparse ? "sparse" : "dense";
  json levels = json::array();
  double total = 0;
  HierarchyCallbacks cb;
  cb.level_done = [&](const HierarchyLevel& h, const SolverSummary& summary, const std::vector<float>&) {
    const PassStats probe = backend->Cost(h.params, 7);
    const double psnr = test.empty() ? 0.0 : MeanPsnr(ScoreViews(backend.get(), h.params, test, kDefaultMinBoxOpacity));
    const int64_t bricks = h.shape.StoredBricks(), bricks_of = BrickCount(h.shape.n), cells = h.shape.StoredCells();
    const double per_iteration = summary.iterations > 0 ? summary.seconds_total / summary.iterations : 0.0;
    total += summary.seconds_total;
    json l{{"mode", mode},
           {"level", h.level},
           {"n", h.shape.n},
           {"stored_cells", cells},
           {"bricks", bricks},
           {"bricks_of", bricks_of},
           {"params", h.shape.ParamCount()},
           {"rays", h.rays},
           {"samples_per_ray", static_cast<double>(probe.samples) / std::max<int64_t>(1, probe.rays)},
           {"seconds_per_iteration", per_iteration},
           {"seconds_linearize_pass", PerPass(summary.seconds_linearize, summary.linearize_passes)},
           {"seconds_jtj_pass", PerPass(summary.seconds_cg, summary.jtj_passes)},
           {"seconds_cost_pass", probe.seconds},
           {"memory_bytes", h.memory.Total()},
           {"test_psnr", psnr},
           {"solver", summary.ToJson()}};
    std::printf("%-6s level %d  %4d^3  %9lld cells (%6lld of %6lld bricks)  %6.1f samples/ray  %7.2f s/it "
                "(linearize %.2f, J^T J p %.3f, cost %.3f s)  %7.1f MiB  held-out %.2f dB\n",
                mode, h.level, h.shape.n, static_cast<long long>(cells), static_cast<long long>(bricks),
                static_cast<long long>(bricks_of), l["samples_per_ray"].get<double>(), per_iteration,
                l["seconds_linearize_pass"].get<double>(), l["seconds_jtj_pass"].get<double>(), probe.seconds,
                h.memory.Total() / 1048576.0, psnr);
    std::fflush(stdout);
    levels.push_back(l);
  };
  SolveHierarchy(backend.get(), geometry, views, ho, HierarchyStart{}, cb);
  return {{"mode", mode}, {"backend", backend->Describe()}, {"levels", levels}, {"solver_seconds", total}};
}

}  // namespace

json RunCpuHierarchy(const CpuHierarchySettings& s) {
  const std::filesystem::path ws = s.workspace;
  const Scene scene = ReadScene(ws / "scene.json");
  const std::vector<PosedImage> train = LoadImages(scene, ws, Split::kTrain);
  const std::vector<PosedImage> test = LoadImages(scene, ws, Split::kTest);
  std::printf("%s: %zu training and %zu held-out photos; %d levels from %d^3, %d GN iterations a level\n",
              s.workspace.c_str(), train.size(), test.size(), s.levels, s.start, s.iterations);
  json out{{"workspace", s.workspace}, {"levels", s.levels}, {"start", s.start}, {"iterations", s.iterations},
           {"occupancy", {{"min_opacity", s.occupancy.min_opacity}, {"dilation", s.occupancy.dilation}}}};
  std::printf("sparse levels keep cells of opacity >= %g, dilated %d cells\n", s.occupancy.min_opacity,
              s.occupancy.dilation);
  if (s.sparse) out["sparse"] = RunMode(s, true, scene, train, test);
  if (s.dense) out["dense"] = RunMode(s, false, scene, train, test);
  if (s.sparse && s.dense) {
    const json& a = out["sparse"]["levels"];
    const json& b = out["dense"]["levels"];
    for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
      const double speedup = a[i]["seconds_per_iteration"].get<double>() > 0
                                 ? b[i]["seconds_per_iteration"].get<double>() / a[i]["seconds_per_iteration"].get<double>()
                                 : 0.0;
      const double dpsnr = a[i]["test_psnr"].get<double>() - b[i]["test_psnr"].get<double>();
      std::printf("level %zu: sparse GN iteration %.2fx faster than dense, held-out %+.2f dB, memory %.2fx\n", i,
                  speedup, dpsnr,
                  static_cast<double>(a[i]["memory_bytes"].get<int64_t>()) / b[i]["memory_bytes"].get<int64_t>());
      out["ratios"].push_back({{"level", i}, {"iteration_speedup", speedup}, {"test_psnr_delta_db", dpsnr}});
    }
  }
  return out;
}

}  // namespace perf::bench
