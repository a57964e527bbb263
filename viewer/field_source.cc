#include "viewer/field_source.h"

#include <nlohmann/json.hpp>

#include "viewer/field_payload.h"

namespace perf::viewer {

namespace fs = std::filesystem;

nlohmann::json FieldSource::Listing() const {
  nlohmann::json levels = nlohmann::json::array();
  const int last = recon::LastCheckpointLevel(workspace_);
  for (int level = 0; level <= last; ++level) {
    const fs::path path = recon::CheckpointPath(workspace_, level);
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) continue;
    levels.push_back({{"level", level}});
  }
  nlohmann::json live = nullptr;
  const std::shared_ptr<const LiveField> l = live_ ? live_() : nullptr;
  if (l) {
    live = {{"level", l->volume.level}, {"iteration", l->iteration}, {"version", l->version},
            {"n", l->volume.shape.n}, {"sh_degree", l->volume.shape.sh_degree}};
  }
  nlohmann::json newest = l ? nlohmann::json("live") : levels.empty() ? nlohmann::json() : levels.back()["level"];
  return {{"levels", levels}, {"live", live}, {"newest", newest}};
}

std::optional<FieldSource::Response> FieldSource::From(Cached& entry, bool gzip) {
  if (!entry.raw) return std::nullopt;
  if (gzip && !entry.gz) entry.gz = std::make_shared<const std::string>(Gzip(*entry.raw));
  return Response{gzip ? entry.gz : entry.raw, gzip};
}

std::optional<FieldSource::Response> FieldSource::Payload(int level, bool gzip) {
  const std::shared_ptr<const LiveField> l = live_ && level < 0 ? live_() : nullptr;
  std::lock_guard<std::mutex> lock(mu_);
  if (l) {
    if (live_cache_.version != l->version || !live_cache_.raw) {
      live_cache_ = {{}, l->version, std::make_shared<const std::string>(FieldPayload(l->volume, l->iteration)), {}};
    }
    return From(live_cache_, gzip);
  }
  if (level < 0) level = recon::LastCheckpointLevel(workspace_);
  if (level < 0) return std::nullopt;
  const fs::path path = recon::CheckpointPath(workspace_, level);
  std::error_code ec;
  const fs::file_time_type mtime = fs::last_write_time(path, ec);
  if (ec) return std::nullopt;
  Cached& entry = levels_[level];
  if (!entry.raw || entry.mtime != mtime) {
    entry = {mtime, 0, std::make_shared<const std::string>(FieldPayload(recon::ReadCheckpoint(path))), {}};
  }
  return From(entry, gzip);
}

}  // namespace perf::viewer
