// The page of `perf view` while a command runs (`perf run --view`, `perf reconstruct --view`): the
// same server on the workspace, started before the command's first stage, with /api/status saying
// the stage, the level and iteration, this level's ETA and the newest preview render
// (WORKSPACE/preview/, written each iteration with --view), and the solver's newest volume for the
// page's field (/api/field, field_source.h). The command reports through the
// methods below (cheap: a lock and a few numbers); the server never waits on the command.
#pragma once

#include <chrono>
#include <filesystem>
#include <memory>
#include <mutex>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <thread>

#include "viewer/field_source.h"
#include "viewer/view_server.h"

namespace perf::viewer {

class LiveView {
 public:
  // Binds (throws IoError like ViewServer::Bind) and serves from a thread of its own.
  explicit LiveView(ViewOptions options);
  ~LiveView();  // stops serving
  LiveView(const LiveView&) = delete;
  LiveView& operator=(const LiveView&) = delete;

  std::string Url() const { return server_.Url(); }
  int port() const { return port_; }

  void Stage(const std::string& stage);
  void Iteration(int level, int levels, int iteration, int iterations);
  // "finished" or "stopped" (Ctrl-C): the page says so.
  void End(const std::string& state);
  // The solver's volume after `iteration` (ReconstructOptions::on_volume), which the page draws.
  void Volume(recon::Checkpoint volume, int iteration);

 private:
  nlohmann::json Status() const;

  ViewServer server_;
  int port_ = 0;
  std::thread thread_;
  mutable std::mutex mu_;
  std::string state_ = "starting", stage_;
  int level_ = 0, levels_ = 0, iteration_ = 0, iterations_ = 0;
  std::chrono::steady_clock::time_point level_start_ = std::chrono::steady_clock::now();
  double eta_seconds_ = -1;
  std::shared_ptr<const LiveField> field_;  // the newest Volume
};

}  // namespace perf::viewer
