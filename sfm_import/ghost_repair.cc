#include "sfm_import/ghost_repair.h"

#include <algorithm>
#include <cstdio>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/stopwatch.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_runner.h"
#include "sfm_import/importer.h"

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

}  // namespace

nlohmann::json RepairResult::ToJson() const {
  return {{"attempted", attempted}, {"used", used}, {"why", why}, {"model", model.string()},
          {"before", CheckJson(before)}, {"after", after.registered > 0 ? CheckJson(after) : nlohmann::json()},
          {"seconds", seconds}};
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
  // A decision recorded for this model (same folder, files no newer) stands.
  const double model_time = ModelTime(o.model);
  const std::string model_path = fs::absolute(o.model).lexically_normal().string();
  std::error_code ec;
  if (fs::exists(record, ec)) {
    const nlohmann::json j = nlohmann::json::parse(ReadFileToString(record), nullptr, false);
    if (j.is_object() && j.value("user_model", "") == model_path &&
        j.value("user_model_time", -1.0) == model_time &&
        (!j.value("used", false) || fs::exists(repaired / "images.bin", ec))) {
      r.attempted = true;
      r.used = j.value("used", false);
      r.why = j.value("why", "");
      if (r.used) r.model = repaired;
      Say(o, StrCat("repair: as decided before (", record.string(), "): ", r.why));
      return r;
    }
  }
  r.attempted = true;
  Say(o, StrCat("repair: the model has ", r.before.ghosts.size(), " ghost group(s) (", r.before.ghost_photos,
                " photos placed as a second copy of the object): making the model again from the photos (perf sfm "
                "into ", dir.string(), "; --no-repair imports it as given)"));
  SfmOptions so;
  so.images = r.images;
  if (given.cameras.size() == 1) {  // COLMAP starts from the given camera (one for all photos)
    const colmap::Camera& cam = given.cameras.begin()->second;
    if (const colmap::CameraModelInfo* info = colmap::FindCameraModel(cam.model_id)) {
      so.camera_model = std::string(info->name);
      for (double p : cam.params) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.10g", p);
        if (!so.camera_params.empty()) so.camera_params += ',';
        so.camera_params += buf;
      }
    }
  }
  so.workspace = dir;
  so.num_threads = o.threads > 0 ? o.threads : -1;
  so.check_stop = o.check_stop;
  so.progress = [&](const std::string& line) { Say(o, "repair: " + line); };
  try {
    const SfmResult sfm = RunSfm(so);
    const colmap::Reconstruction made = colmap::ReadReconstruction(sfm.sparse_dir);
    r.after = CheckModel(made);
    std::string why;
    r.used = RepairIsBetter(r.after, r.before, &why);
    r.why = StrCat(r.used ? "the new model is used: " : "the model is kept: the new one is not better: ", why);
    if (r.used) {
      colmap::WriteReconstruction(repaired, made, colmap::ModelFormat::kBinary);
      r.model = repaired;
    }
  } catch (const Interrupted&) {
    throw;
  } catch (const Error& e) {
    std::string what = e.what();
    what = what.substr(0, what.find('\n'));
    r.why = "the model is kept: perf sfm could not make a model of the photos (" + what + ")";
  }
  r.seconds = SecondsSince(start);
  EnsureWritableDirectory(dir);
  nlohmann::json j = r.ToJson();
  j["user_model"] = model_path;
  j["user_model_time"] = model_time;
  WriteFileAtomically(record, j.dump(2) + "\n");
  Say(o, "repair: " + r.why);
  return r;
}

}  // namespace perf
