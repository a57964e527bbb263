// One `perf reconstruct` run's state, shared by its controller (reconstruct.cc) and its hierarchy
// callbacks (LevelMonitor): what was set up, loaded and chosen, the log, and the result so far.
// Internal to run/.
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/comm.h"
#include "common/json_log.h"
#include "recon_cuda/backends/distributed_backend.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/run/box_check.h"
#include "recon_cuda/run/previous_run.h"
#include "recon_cuda/run/reconstruct.h"
#include "workspace/scene.h"

namespace perf::recon {

struct ReconstructRun {
  const ReconstructOptions& options;
  SingleProcess single;
  Communicator& comm;
  const bool root;  // rank 0: writes the workspace and reports

  std::filesystem::path scene_path;
  Scene scene;  // its box grows where the object goes on (grow_box)
  VolumeGeometry geometry;
  std::unique_ptr<Communicator> device_comm;  // NCCL, for a CUDA backend with several ranks
  std::unique_ptr<Backend> backend;
  DistributedBackend* ranks = nullptr;  // with several ranks: sums the passes across them
  int levels = 0;
  HierarchyOptions hierarchy;
  std::vector<ViewFrustum> train_views;             // every rank's
  std::vector<std::string> train_names;             // every rank's, scene.json order
  std::vector<PosedImage> train, test;              // this rank's share
  // The photo previews render (in this rank's share): ReconstructOptions::preview_image where
  // the share holds it, else the first held-out view, else the first training view.
  const PosedImage* preview = nullptr;
  int64_t test_views = 0;                           // every rank's
  std::optional<PreviousRun> previous;  // a fresh start's: the earlier run's files, aside
  JsonLog log;                          // rank 0's recon/log.jsonl
  ReconstructResult result;

  explicit ReconstructRun(const ReconstructOptions& o)
      : options(o), comm(o.comm != nullptr ? *o.comm : single), root(comm.IsRoot()) {}

  void Emit(const ReconstructOptions::Event& e) const {
    if (options.on_event && root) options.on_event(e);
  }
  void Say(const std::string& line) const {
    ReconstructOptions::Event e;
    e.message = line;
    Emit(e);
  }
};

}  // namespace perf::recon
