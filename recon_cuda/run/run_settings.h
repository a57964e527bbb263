// The settings that shape a reconstruction's result, recorded with its checkpoints
// (recon/settings.json, written when a run starts from level 1), so that a resume can tell
// whether it would continue the same fit: `perf run` starts over when they changed (a preset or
// an option that differs from the last run's), `perf reconstruct --resume` names the changes and
// continues. Where the work runs (device, threads, ranks) and what is only reported (previews,
// --eval-every) are not part of them.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace perf::recon {

struct ReconstructOptions;

// One flat object: the options as asked for (levels 0 means "from the photos").
nlohmann::json RunSettings(const ReconstructOptions& o);

std::filesystem::path RunSettingsPath(const std::filesystem::path& workspace);  // recon/settings.json

// The recorded settings of the run whose checkpoints are in `workspace`; nullopt when none were
// recorded (a run of an older perf) or the file does not parse.
std::optional<nlohmann::json> ReadRunSettings(const std::filesystem::path& workspace);

// "sh_degree 1 -> 0", one per setting that differs (a setting only one side has counts), in key
// order; empty when the two are the same.
std::vector<std::string> SettingsChanges(const nlohmann::json& before, const nlohmann::json& now);

}  // namespace perf::recon
