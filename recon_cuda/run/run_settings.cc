#include "recon_cuda/run/run_settings.h"

#include <charconv>
#include <cstdlib>
#include <set>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "recon_cuda/run/reconstruct_options.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace perf::recon {
namespace {

template <typename E>
const char* AutoOnOff(E e) {
  return e == E::kOn ? "on" : e == E::kOff ? "off" : "auto";
}

const char* BackgroundWord(BackgroundChoice b) {
  return b == BackgroundChoice::kFixed ? "fixed" : b == BackgroundChoice::kLearn ? "learn" : "auto";
}

std::string Show(const json& v) { return v.is_null() ? std::string("(not set)") : v.dump(); }

// A float option as written on the command line (0.1, not 0.10000000149011612): the shortest
// decimal that reads back as the float.
double Decimal(float v) {
  char buf[32];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  return ec == std::errc() ? std::strtod(std::string(buf, end).c_str(), nullptr) : v;
}

}  // namespace

json RunSettings(const ReconstructOptions& o) {
  const SolverOptions& s = o.solver;
  const ResidualSettings& r = o.residuals;
  json j{{"solver", SolverName(s.type)},
         {"levels", o.levels},
         {"max_resolution", o.max_resolution},
         {"start_resolution", o.start_resolution},
         {"iterations", o.iterations},
         {"level_iterations", o.level_iterations},
         {"cost_tolerance", s.cost_tolerance},
         {"max_cg_iterations", s.max_cg_iterations},
         {"cg_exit_ratio", s.cg_exit_ratio},
         {"damping", s.damping},
         {"diagonal_floor", s.diagonal_floor},
         {"hold_at_bounds", s.hold_at_bounds},
         {"initial_step", s.initial_step},
         {"line_search_ray_stride", s.line_search_ray_stride},
         {"jtj_ray_stride", s.jtj_ray_stride},
         {"smooth_grid", s.smooth_grid},
         {"smooth_shells", s.smooth_shells},
         {"exposure_prior", s.exposure_prior},
         {"seed", s.seed},
         {"adam_lr", {Decimal(s.adam.lr_colour), Decimal(s.adam.lr_density), Decimal(s.adam.lr_opacity)}},
         {"exposure", AutoOnOff(o.exposure)},
         {"poses", AutoOnOff(o.poses)},
         {"pose_prior", o.PosePrior()},
         {"refine_poses_from", o.refine_poses_from},
         {"refine_focal", o.refine_focal},
         {"sh_degree", o.sh_degree},
         {"sh_from_level", o.sh_from_level},
         {"lambda", Decimal(r.lambda)},
         {"stop_transmittance", Decimal(r.stop_transmittance)},
         {"jitter", r.jitter},
         {"pixel_jitter", r.pixel_jitter},
         {"use_alpha", r.use_alpha},
         {"alpha_weight", Decimal(r.alpha_weight)},
         {"robust_scale", Decimal(r.robust_scale)},
         {"background", BackgroundWord(o.background)},
         {"init_opacity", o.init.box_opacity},
         {"init_shells_from_photos", o.init_shells_from_photos},
         {"pyramid", o.pyramid},
         {"dense", o.dense},
         {"grow_box", o.grow_box},
         {"sparse_min_opacity", Decimal(o.occupancy.min_opacity)},
         {"sparse_dilation", o.occupancy.dilation}};
  // What the file will read back as (an infinite ratio is written as null), so that a run's own
  // settings compare equal with their record.
  return json::parse(j.dump());
}

fs::path RunSettingsPath(const fs::path& workspace) { return workspace / "recon" / "settings.json"; }

std::optional<json> ReadRunSettings(const fs::path& workspace) {
  const fs::path path = RunSettingsPath(workspace);
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return std::nullopt;
  try {
    json j = json::parse(ReadFileToString(path), nullptr, false);
    if (j.is_object()) return j;
  } catch (const Error&) {
    // unreadable: as if not recorded
  }
  return std::nullopt;
}

std::vector<std::string> SettingsChanges(const json& before, const json& now) {
  std::set<std::string> keys;
  for (const json* side : {&before, &now}) {
    if (!side->is_object()) continue;
    for (auto it = side->begin(); it != side->end(); ++it) keys.insert(it.key());
  }
  std::vector<std::string> changes;
  for (const std::string& k : keys) {
    const json a = before.is_object() ? before.value(k, json()) : json();
    const json b = now.is_object() ? now.value(k, json()) : json();
    if (a != b) changes.push_back(k + " " + Show(a) + " -> " + Show(b));
  }
  return changes;
}

}  // namespace perf::recon
