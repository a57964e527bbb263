// The volumes perf view's page can draw (/api/fields, /api/field): each level's checkpoint in
// WORKSPACE/recon, and while a solve runs (perf run --view, perf reconstruct --view) the solver's
// newest volume, handed over by the command (SetLive). Payloads (field_payload.h) are made once
// per checkpoint file or live version and kept, with their gzip copy, for the next request.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>

#include "recon_cuda/data/checkpoint.h"

namespace perf::viewer {

// The solver's volume during a run: a level's parameters after `iteration` iterations.
struct LiveField {
  recon::Checkpoint volume;
  int iteration = 0;
  uint64_t version = 0;  // grows with every volume handed over
};

class FieldSource {
 public:
  explicit FieldSource(std::filesystem::path workspace) : workspace_(std::move(workspace)) {}

  // A running command's newest volume (nullptr before the first); set once, before serving.
  void SetLive(std::function<std::shared_ptr<const LiveField>()> live) { live_ = std::move(live); }

  // {"levels": [{"level", "n", "m", "bricks", "sh_degree"}...] of the checkpoints there,
  //  "live": {"level", "iteration", "version"} or null, "newest": "live" or the last level or null}.
  nlohmann::json Listing() const;

  struct Response {
    std::shared_ptr<const std::string> bytes;
    bool gzip = false;
  };
  // The payload of `level` (a checkpoint's level, or -1: the newest, the live volume when there is
  // one), gzip'd when the client takes it; nullopt when there is no such volume. Throws the
  // checkpoint reader's errors for a damaged file.
  std::optional<Response> Payload(int level, bool gzip);

 private:
  struct Cached {
    std::filesystem::file_time_type mtime{};
    uint64_t version = 0;
    std::shared_ptr<const std::string> raw, gz;
  };
  std::optional<Response> From(Cached& entry, bool gzip);

  std::filesystem::path workspace_;
  std::function<std::shared_ptr<const LiveField>()> live_;
  std::mutex mu_;
  std::map<int, Cached> levels_;  // by checkpoint level
  Cached live_cache_;
};

}  // namespace perf::viewer
