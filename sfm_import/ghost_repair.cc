#include "sfm_import/ghost_repair.h"

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>
#include <utility>
#include <vector>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/stopwatch.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_runner.h"
#include "sfm_import/ghost_move.h"
#include "sfm_import/ghost_register.h"
#include "sfm_import/importer.h"
#include "sfm_import/model_align.h"
#include "sfm_import/sfm_matching_time.h"
#include "workspace/image_io.h"

namespace perf {
namespace {

namespace fs = std::filesystem;

void Say(const RepairOptions& o, const std::string& line) {
  if (o.say) o.say(line);
}

// The newest time of the model's files, as a number for repair.json.
double ModelTime(const fs::path& model) {
  double newest = 0;
  std::error_code ec;
  for (fs::directory_iterator it(model, ec), end; !ec && it != end; it.increment(ec)) {
    const auto t = fs::last_write_time(it->path(), ec);
    if (!ec) newest = std::max(newest, std::chrono::duration<double>(t.time_since_epoch()).count());
  }
  return newest;
}

nlohmann::json CheckJson(const ModelCheck& c) {
  nlohmann::json ghosts = nlohmann::json::array();
  for (const GhostGroup& g : c.ghosts) ghosts.push_back({{"photos", g.names}, {"points", g.points}, {"separation", g.separation}});
  return {{"registered", c.registered}, {"points", c.points}, {"mean_error", c.mean_error},
          {"poses_look_wrong", c.bad_poses.size()}, {"ghost_groups", ghosts}, {"summary", c.Describe()}};
}

// perf sfm of the photos with its own default camera (SIMPLE_RADIAL, one focal length: the given
// model's OPENCV camera bent bonsai's remakes, docs/tuning.md "One focal length for mapping"),
// but a fisheye camera of the given model kept as its model and starting parameters.
SfmOptions RepairSfmOptions(const colmap::Reconstruction& given, const fs::path& images, const fs::path& dir,
                            const RepairOptions& o) {
  SfmOptions so;
  so.images = images;
  if (given.cameras.size() == 1) {
    const colmap::Camera& cam = given.cameras.begin()->second;
    const colmap::CameraModelInfo* info = colmap::FindCameraModel(cam.model_id);
    if (info != nullptr && info->name.find("FISHEYE") != std::string_view::npos) {
      so.camera_model = std::string(info->name);
      so.camera_params = CameraParamsArgument(cam);
    }
  }
  so.workspace = dir;
  so.num_threads = o.threads > 0 ? o.threads : -1;
  so.check_stop = o.check_stop;
  so.check_model = ObjectModelDoubtOf;  // made again from every pair where it looks wrong
  so.seconds_left = o.seconds_left;
  so.progress = [&o](const std::string& line) { Say(o, "repair: " + line); };
  return so;
}

std::string DescribeAlignment(const ModelAlignment& a) {
  if (a.photos == 0) return "the new model is left in its own frame (fewer than 3 photos in common with the given one)";
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "the new model put in the given model's frame by %d photos (scale %.3f; their centres %.1f %% of "
                "the camera distance apart, median)",
                a.photos, a.scale, 100 * a.median_error / std::max(a.camera_radius, 1e-12));
  return buf;
}

// What a COLMAP route over the photos of `given` (perf sfm, or the registration, which also
// extracts every photo's features) takes by SequentialSfmSeconds, at the size of the first photo's
// header (the camera's where it cannot be read). Both routes share it.
double ColmapRouteSeconds(const colmap::Reconstruction& given, const SfmOptions& so) {
  if (given.images.empty()) return 0;
  const colmap::Image& first = given.images.begin()->second;
  double w = 0, h = 0;
  try {
    const CameraTags tags = ReadCameraTags(so.images / first.name);
    w = tags.width, h = tags.height;
  } catch (const Error&) {  // the camera's size instead; COLMAP will name the photo
    if (const auto cam = given.cameras.find(first.camera_id); cam != given.cameras.end()) {
      w = static_cast<double>(cam->second.width), h = static_cast<double>(cam->second.height);
    }
  }
  const double scale = std::min(1.0, so.max_image_size / std::max({w, h, 1.0}));
  return SequentialSfmSeconds(so, static_cast<int>(given.images.size()), w * h * scale * scale / 1e6);
}

std::string Join(const std::vector<std::string>& parts) {
  std::string out;
  for (const std::string& p : parts) out += (out.empty() ? "" : "; ") + p;
  return out;
}

}  // namespace

nlohmann::json RepairResult::ToJson() const {
  return {{"attempted", attempted}, {"used", used}, {"why", why}, {"model", model.string()},
          {"before", CheckJson(before)}, {"after", after.registered > 0 ? CheckJson(after) : nlohmann::json()},
          {"route", route}, {"tries", tries}, {"seconds", seconds}};
}

std::vector<std::vector<std::string>> RepairResult::TurnUnknown() const {
  std::vector<std::vector<std::string>> groups;
  if (!used || route != "move") return groups;
  for (const GhostGroup& g : before.ghosts) groups.push_back(g.names);
  return groups;
}

RepairResult RepairModel(const RepairOptions& o) {
  const auto start = WallClock::now();
  RepairResult r;
  r.model = o.model;
  r.images = o.images.empty() ? DefaultColmapImages(o.model) : o.images;
  const colmap::Reconstruction given = colmap::ReadReconstruction(o.model);
  r.before = CheckModel(given);
  if (r.before.ghosts.empty()) return r;
  const fs::path dir = o.workspace / "repair", record = dir / "repair.json", repaired = o.workspace / "sparse_repaired";
  if (!o.repair) {
    Say(o, StrCat("the model has ", r.before.ghosts.size(), " ghost group(s) (", r.before.ghost_photos,
                  " photos): imported as given (--no-repair)"));
    return r;
  }
  // A decision recorded for this model (same folder, files no newer) by these rules stands; one
  // by earlier rules (before the model made again came first: no "rules"), or one that left a
  // route out for the time budget, is made again.
  constexpr int kRules = 2;
  const double model_time = ModelTime(o.model);
  const std::string model_path = fs::absolute(o.model).lexically_normal().string();
  std::error_code ec;
  if (fs::exists(record, ec)) {
    const nlohmann::json j = nlohmann::json::parse(ReadFileToString(record), nullptr, false);
    if (j.is_object() && j.value("rules", 1) == kRules && !j.value("skipped_for_time", false) &&
        j.value("user_model", "") == model_path &&
        j.value("user_model_time", -1.0) == model_time &&
        (!j.value("used", false) || fs::exists(repaired / "images.bin", ec))) {
      r.attempted = true;
      r.used = j.value("used", false);
      r.why = j.value("why", "");
      r.route = j.value("route", "");
      if (r.used) r.model = repaired;
      Say(o, StrCat("repair: as decided before (", record.string(), "): ", r.why));
      return r;
    }
  }
  r.attempted = true;
  Say(o, StrCat("repair: the model has ", r.before.ghosts.size(), " ghost group(s) (", r.before.ghost_photos,
                " photos placed as a second copy of the object): repairing it (COLMAP, in ", dir.string(),
                "; --no-repair imports the model as given)"));
  std::set<std::string> group;
  for (const GhostGroup& g : r.before.ghosts) group.insert(g.names.begin(), g.names.end());
  // `made`'s check against the given model's decides; `check` is CheckModel(made).
  const auto decide = [&](const std::string& route, const colmap::Reconstruction& made, ModelCheck check,
                          const std::string& said) {
    r.after = std::move(check);
    std::string why;
    r.used = RepairIsBetter(r.after, r.before, &why);
    r.route = route;
    r.why = StrCat(r.used ? "the model " + said + " is used: " : "the model " + said + " is not better: ", why);
    r.tries.push_back(r.why);
    Say(o, "repair: " + r.why);
    if (r.used) {
      colmap::WriteReconstruction(repaired, made, colmap::ModelFormat::kBinary);
      r.model = repaired;
    }
  };
  const auto tried = [&](const std::string& what) {
    r.tries.push_back(what);
    Say(o, "repair: " + what);
  };
  const auto failed = [&](const std::string& what, const Error& e) {
    const std::string text = e.what();
    tried(what + " (" + text.substr(0, text.find('\n')) + ")");
  };
  // A model made again has no ghost to hide in and one focal length; put in the user's frame.
  const SfmOptions sfm_options = RepairSfmOptions(given, r.images, dir, o);
  // Under perf run's time budget a COLMAP route runs only where its estimate is at most 80 % of
  // the time left (the rest for the reconstruction); otherwise it says so and is not tried.
  const double colmap_seconds = o.seconds_left ? ColmapRouteSeconds(given, sfm_options) : 0;
  bool skipped_for_time = false;
  const auto fits_budget = [&](const std::string& what) {
    if (!o.seconds_left) return true;
    const double left = o.seconds_left();
    if (colmap_seconds <= 0.8 * left) return true;
    tried(StrCat(what, " would take about ", static_cast<int>(colmap_seconds), " s, more than the time budget can give it (",
                 static_cast<int>(std::max(0.0, left)), " s left): not tried"));
    skipped_for_time = true;
    return false;
  };
  if (o.routes.count("sfm") && fits_budget("making the model again")) {
    try {
      Say(o, "repair: making the model again from the photos (perf sfm into " + dir.string() + ")");
      colmap::Reconstruction made = colmap::ReadReconstruction(RunSfm(sfm_options).sparse_dir);
      std::set<std::string> doubted = group;
      for (const auto& [name, why] : r.before.bad_poses) doubted.insert(name);
      Say(o, "repair: " + DescribeAlignment(AlignModelOnto(made, given, doubted)));
      decide("sfm", made, CheckModel(made), "made again by perf sfm");
    } catch (const Interrupted&) {
      throw;
    } catch (const Error& e) {
      failed("perf sfm could not make a model of the photos", e);
    }
  }
  if (!r.used && o.routes.count("register") && fits_budget("registering the group again")) {
    try {
      RegisterGroupOptions ro;
      ro.images = r.images;
      ro.dir = dir / "register";
      ro.threads = o.threads > 0 ? o.threads : -1;
      ro.say = [&](const std::string& line) { Say(o, "repair: " + line); };
      ro.check_stop = o.check_stop;
      const GroupRegistration reg = RegisterGroupAgain(given, group, ro);
      // A photo COLMAP placed where its pose looks wrong is left out by the import, as in any model
      // (kept at its given pose, bonsai's DSCF5605 scored 12.3 dB, moved onto the object 12.6 dB,
      // against 16.4 dB with the whole ghost group as given: docs/tuning.md).
      ModelCheck check = CheckModel(reg.model);
      const size_t placed =
          std::count_if(reg.placed.begin(), reg.placed.end(), [&](const std::string& n) { return !check.bad_poses.count(n); });
      if (placed == 0) {
        tried(StrCat("COLMAP registered none of the group's ", group.size(), " photos again"));
      } else {
        decide("register", reg.model, std::move(check),
               StrCat("with the group registered again (", placed, " of ", group.size(), " placed",
                      placed < group.size() ? StrCat("; ", group.size() - placed, " left out or placed wrongly") : std::string(),
                      ")"));
      }
    } catch (const Interrupted&) {
      throw;
    } catch (const Error& e) {
      failed("COLMAP could not register the group again", e);
    }
  }
  if (!r.used && o.routes.count("move")) {
    const colmap::Reconstruction moved = MoveGhostsOntoObject(given, r.before.ghosts);
    decide("move", moved, CheckModel(moved), "with each group moved onto the object");
  }
  r.why = r.used ? r.tries.back() : "the model is kept: " + Join(r.tries);
  r.seconds = SecondsSince(start);
  EnsureWritableDirectory(dir);
  nlohmann::json j = r.ToJson();
  j["user_model"] = model_path;
  j["user_model_time"] = model_time;
  j["rules"] = kRules;
  j["skipped_for_time"] = skipped_for_time;
  WriteFileAtomically(record, j.dump(2) + "\n");
  if (!r.used) Say(o, "repair: " + r.why);
  return r;
}

}  // namespace perf
