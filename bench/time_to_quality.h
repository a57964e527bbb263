// The GPU benchmark's engine (gpu_time_to_quality.cc is its command line): the hierarchy of
// perf reconstruct run with one solver on any backend, the held-out PSNR recorded against solver
// time, and the results written as JSON + SVG after every evaluation and every level, atomically,
// so that a run killed by a time limit still leaves figures. A time budget and a stop flag end a
// run cleanly at the next solver iteration. No CUDA here: the tests drive it with the CPU
// backend on a tiny scene and a fake clock (bench/time_to_quality_test.cc).
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "recon_cuda/core/render_rule.h"
#include "recon_cuda/solve/backend.h"
#include "recon_cuda/solve/solver.h"

namespace perf::bench {

struct View {
  std::string name;
  bool train = true;
  recon::PinholeCamera<float> camera{};
  int width = 0, height = 0;
  const uint8_t* rgb = nullptr;    // [height, width, 3] in BenchData::pixels
  const uint8_t* alpha = nullptr;  // [height, width] in BenchData::alphas, or nullptr
};

// What perf_bench_prep + bench/decode_images.py wrote. With alpha (every photo had one), the
// benchmark runs as perf reconstruct does by default: shells fixed at the background, the
// opacity residual fitting the alpha.
struct BenchData {
  recon::VolumeGeometry geometry;
  float background[3] = {1, 1, 1};
  bool alpha = false;
  std::vector<View> views;
  std::vector<uint8_t> pixels;  // images.u8
  std::vector<uint8_t> alphas;  // alpha.u8
};

// Reads DIR/bench.json, DIR/images.u8 and (with alpha) DIR/alpha.u8; throws IoError naming the
// file and the step that makes it.
BenchData LoadBenchData(const std::filesystem::path& dir);

// The view as a training or held-out image, box-downscaled by an integer factor (intrinsics
// scaled as training_data.h Downscaled does).
recon::PosedImage ToPosed(const View& v, int factor);

struct BenchSettings {
  int levels = 4, start = 32, gn_iterations = 10, adam_steps = 200, adam_eval_every = 20;
  uint32_t seed = 1;
  float min_box_opacity = recon::kDefaultMinBoxOpacity;
  bool sparse = true;  // levels after the first keep the occupied bricks (hierarchy.h)
  recon::SolverOptions solver;  // GN settings and Adam's learning rates
};

// One solver's run, as far as it got.
struct SolverRun {
  nlohmann::json points = nlohmann::json::array(), levels = nlohmann::json::array(),
                 passes = nlohmann::json::object();
  std::vector<std::pair<double, double>> curve;  // (solver seconds, held-out PSNR)
  double seconds = 0, final_psnr = 0;
  int64_t peak_memory = 0;
  bool complete = false;  // every level ran to its iteration count
  std::string stopped;    // why it ended early: "time budget", "signal", or "" (not stopped)
};

// How a run is driven. clock: monotonic seconds (WallClock by default; the tests pass a fake
// one); deadline: in the clock's seconds, the run stops at the first solver iteration that ends
// after it (and starts no level after it); stop: a flag (a signal handler's) read likewise;
// memory_in_use: device memory in use, for the peak (CudaMemoryInUse), or none; on_update:
// called after every evaluation and every level with the run so far (the writer).
struct RunContext {
  std::function<double()> clock;
  double deadline = 1e300;
  const std::atomic<bool>* stop = nullptr;
  std::function<int64_t()> memory_in_use;
  std::function<void(const SolverRun&)> on_update;
};

// Runs the hierarchy with `type` on `backend` into *run (filled as it goes, so on_update sees
// it). Throws Error when a level's solve fails (non-finite cost).
void RunHierarchy(recon::Backend* backend, const BenchData& data, recon::SolverType type, const BenchSettings& s,
                  const RunContext& context, SolverRun* run);

// First solver time at which the curve reaches `psnr` (-1: never).
double TimeTo(const std::vector<std::pair<double, double>>& curve, double psnr);

// Peak HBM bandwidth by device name (GB/s); 0 if unknown (then --bandwidth-gbs is needed).
double KnownBandwidth(const std::string& name);

// The results file: `header` (format, device, commit, settings...) plus every run so far, the
// comparison, and the roofline of the last level whose passes were timed. bandwidth_gbs 0: no
// bounds.
nlohmann::json ResultsJson(const nlohmann::json& header, const std::map<std::string, SolverRun>& runs,
                           double bandwidth_gbs);

// PSNR against solver time for every run, as an SVG (the paper's figure 1).
std::string ResultsSvg(const std::map<std::string, SolverRun>& runs, const std::string& device);

// Writes <dir>/<tag>.json and <tag>.svg, each atomically (temporary file, then rename), so that
// a reader (or a kill) never sees half a file.
struct ResultsFiles {
  std::filesystem::path json_path, svg_path;
  ResultsFiles(const std::filesystem::path& dir, const std::string& tag);
  void Write(const nlohmann::json& header, const std::map<std::string, SolverRun>& runs, double bandwidth_gbs,
             const std::string& device) const;
};

}  // namespace perf::bench
