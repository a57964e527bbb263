#include "viewer/live_view.h"

#include <nlohmann/json.hpp>
#include <system_error>

namespace perf::viewer {

namespace fs = std::filesystem;

namespace {

ViewOptions Live(ViewOptions o) {
  o.require_scene = false;
  return o;
}

// The newest preview (LevelMonitor::WritePreview: preview/recon_l<L>_i<I>.png), relative to the
// workspace; empty when there is none.
std::string NewestPreview(const fs::path& workspace) {
  std::error_code ec;
  fs::file_time_type newest{};
  std::string best;
  for (const auto& e : fs::directory_iterator(workspace / "preview", ec)) {
    if (e.path().extension() != ".png") continue;
    const fs::file_time_type t = e.last_write_time(ec);
    if (!ec && (best.empty() || t > newest)) {
      newest = t;
      best = "preview/" + e.path().filename().string();
    }
  }
  return best;
}

}  // namespace

LiveView::LiveView(ViewOptions options) : server_(Live(options)) {
  const fs::path workspace = options.workspace;
  server_.SetLiveStatus([this, workspace] {
    nlohmann::json j = Status();
    j["preview"] = NewestPreview(workspace);
    return j;
  });
  server_.SetLiveField([this] {
    std::lock_guard<std::mutex> lock(mu_);
    return field_;
  });
  port_ = server_.Bind();
  thread_ = std::thread([this] { server_.Serve(); });
}

LiveView::~LiveView() {
  server_.Stop();
  if (thread_.joinable()) thread_.join();
}

void LiveView::Stage(const std::string& stage) {
  std::lock_guard<std::mutex> lock(mu_);
  stage_ = stage;
  state_ = "running";
  eta_seconds_ = -1;
}

void LiveView::Iteration(int level, int levels, int iteration, int iterations) {
  std::lock_guard<std::mutex> lock(mu_);
  const auto now = std::chrono::steady_clock::now();
  if (level != level_ || iteration < iteration_) level_start_ = now;  // a new level (its first iteration)
  const double spent = std::chrono::duration<double>(now - level_start_).count();
  // This level's iterations so far, each as long as their mean (the first only starts the clock).
  eta_seconds_ = iteration > 1 ? spent / (iteration - 1) * (iterations - iteration) : -1;
  level_ = level;
  levels_ = levels;
  iteration_ = iteration;
  iterations_ = iterations;
}

void LiveView::Volume(recon::Checkpoint volume, int iteration) {
  auto field = std::make_shared<LiveField>();
  field->volume = std::move(volume);
  field->iteration = iteration;
  std::lock_guard<std::mutex> lock(mu_);
  field->version = field_ ? field_->version + 1 : 1;
  field_ = std::move(field);
}

void LiveView::End(const std::string& state) {
  std::lock_guard<std::mutex> lock(mu_);
  state_ = state;
  eta_seconds_ = -1;
}

nlohmann::json LiveView::Status() const {
  std::lock_guard<std::mutex> lock(mu_);
  return {{"state", state_},   {"stage", stage_},         {"level", level_},          {"levels", levels_},
          {"iteration", iteration_}, {"iterations", iterations_}, {"eta_seconds", eta_seconds_}};
}

}  // namespace perf::viewer
