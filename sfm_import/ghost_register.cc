#include "sfm_import/ghost_register.h"

#include <algorithm>
#include <cstdio>
#include <map>
#include <utility>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/owned_files.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_database.h"
#include "sfm_import/colmap_process.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using namespace sfm_detail;
using Pair = std::pair<std::string, std::string>;

// COLMAP's steps of the registration, in its folder, with the caller's progress and stop.
struct Steps {
  explicit Steps(const RegisterGroupOptions& o) : dir(o.dir), threads(std::to_string(o.threads)) {
    SfmOptions sfm;
    sfm.progress = o.say;
    sfm.check_stop = o.check_stop;
    colmap = ColmapSteps(sfm, FindColmap(sfm.colmap_binary), dir / "colmap.log");
  }
  void Run(const std::vector<std::string>& args, const std::string& stage, const ProgressParser& parse) {
    colmap.RunOrThrow(args, stage, parse);
  }
  fs::path dir;
  std::string threads;
  ColmapSteps colmap;
};

// One extraction per camera of the model, from its parameters (COLMAP keeps them as a prior; the
// steps below hold them fixed), over the model's photos of that camera.
void ExtractFeatures(Steps& steps, const colmap::Reconstruction& given, const fs::path& images, const fs::path& db) {
  std::map<uint32_t, std::string> lists;
  for (const auto& [id, im] : given.images) lists[im.camera_id] += im.name + "\n";
  for (const auto& [camera_id, text] : lists) {
    const colmap::Camera& cam = given.cameras.at(camera_id);
    const colmap::CameraModelInfo* info = colmap::FindCameraModel(cam.model_id);
    if (info == nullptr) throw InputError("the model's cameras", "model", std::to_string(cam.model_id), "not a COLMAP camera model");
    const fs::path list = steps.dir / StrCat("camera_", camera_id, "_images.txt");
    WriteFileAtomically(list, text);
    steps.Run({"feature_extractor", "--database_path", db.string(), "--image_path", images.string(), "--image_list_path",
               list.string(), "--ImageReader.camera_model", std::string(info->name), "--ImageReader.single_camera", "1",
               "--ImageReader.camera_params", CameraParamsArgument(cam), "--SiftExtraction.use_gpu", "0",
               "--SiftExtraction.num_threads", steps.threads},
              "features", ExtractionParser());
  }
}

// The pairs to match: each photo outside the group with those it shares most points with in the
// model (and its capture-order neighbours), the group's with every other photo or their own
// neighbours in capture order.
std::vector<Pair> PairsToMatch(const colmap::Reconstruction& given, const std::set<std::string>& group,
                               const RegisterGroupOptions& o) {
  std::set<Pair> pairs;
  const auto add = [&](const std::string& a, const std::string& b) {
    if (a != b) pairs.insert(a < b ? Pair(a, b) : Pair(b, a));
  };
  std::map<std::pair<uint32_t, uint32_t>, int> shared;
  for (const auto& [pid, p] : given.points3D) {
    for (size_t i = 0; i < p.track.size(); ++i) {
      for (size_t j = i + 1; j < p.track.size(); ++j) {
        const uint32_t a = p.track[i].image_id, b = p.track[j].image_id;
        if (a != b) ++shared[{std::min(a, b), std::max(a, b)}];
      }
    }
  }
  std::map<uint32_t, std::vector<std::pair<int, uint32_t>>> partners;
  for (const auto& [ab, count] : shared) {
    partners[ab.first].push_back({count, ab.second});
    partners[ab.second].push_back({count, ab.first});
  }
  std::vector<std::string> names;
  for (const auto& [id, im] : given.images) names.push_back(im.name);
  std::sort(names.begin(), names.end());
  for (auto& [id, list] : partners) {
    const std::string& a = given.images.at(id).name;
    if (group.count(a)) continue;
    std::sort(list.rbegin(), list.rend());
    int taken = 0;
    for (const auto& [count, other] : list) {
      const std::string& b = given.images.at(other).name;
      if (group.count(b)) continue;
      add(a, b);
      if (++taken == o.covisible_neighbours) break;
    }
  }
  const int n = static_cast<int>(names.size());
  const bool all = static_cast<int64_t>(group.size()) * (n - 1) <= o.all_pairs_limit;
  for (int i = 0; i < n; ++i) {
    const bool in_group = group.count(names[i]) > 0;
    const int reach = in_group ? (all ? n : o.order_neighbours) : 2;
    for (int j = std::max(0, i - reach); j < std::min(n, i + reach + 1); ++j) add(names[i], names[j]);
  }
  return {pairs.begin(), pairs.end()};
}

// The model less the group, in the database's ids, without points: point_triangulator's input.
colmap::Reconstruction BaseModel(const colmap::Reconstruction& given, const std::set<std::string>& group,
                                 const std::map<std::string, colmap::DatabaseImage>& db) {
  colmap::Reconstruction base;
  for (const auto& [id, im] : given.images) {
    const auto found = db.find(im.name);
    if (found == db.end()) throw InputError(im.name, "photo", im.name, "COLMAP did not read it", "check that it is a readable photo");
    if (group.count(im.name)) continue;
    colmap::Image copy = im;
    copy.image_id = found->second.image_id;
    copy.camera_id = found->second.camera_id;
    copy.points2D.clear();
    base.images[copy.image_id] = copy;
    colmap::Camera cam = given.cameras.at(im.camera_id);
    cam.camera_id = copy.camera_id;
    base.cameras[cam.camera_id] = cam;
  }
  return base;
}

// `made` (database ids) back in the user's ids.
colmap::Reconstruction InGivenIds(colmap::Reconstruction made, const colmap::Reconstruction& given) {
  std::map<std::string, const colmap::Image*> by_name;
  for (const auto& [id, im] : given.images) by_name[im.name] = &im;
  std::map<uint32_t, uint32_t> image_ids;
  colmap::Reconstruction out;
  for (auto& [id, im] : made.images) {
    const colmap::Image* g = by_name.at(im.name);
    image_ids[id] = g->image_id;
    im.image_id = g->image_id;
    im.camera_id = g->camera_id;
    out.images[im.image_id] = std::move(im);
  }
  out.cameras = given.cameras;
  out.points3D = std::move(made.points3D);
  for (auto& [pid, p] : out.points3D) {
    for (colmap::TrackElement& t : p.track) t.image_id = image_ids.at(t.image_id);
  }
  return out;
}

}  // namespace

std::string CameraParamsArgument(const colmap::Camera& camera) {
  std::string out;
  for (double p : camera.params) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.17g", p);
    if (!out.empty()) out += ',';
    out += buf;
  }
  return out;
}

GroupRegistration RegisterGroupAgain(const colmap::Reconstruction& given, const std::set<std::string>& group,
                                     const RegisterGroupOptions& o) {
  EnsureWorkFolder(o.dir);  // COLMAP's: its database and models are replaced by each try
  const fs::path db = o.dir / "database.db", base = o.dir / "base", triangulated = o.dir / "triangulated",
                 registered = o.dir / "registered", pairs_path = o.dir / "pairs.txt";
  for (const char* suffix : {"", "-shm", "-wal"}) RemoveOwned(db.string() + suffix);
  for (const fs::path& d : {base, triangulated, registered}) {
    RemoveOwned(d);
    EnsureWritableDirectory(d);
  }
  Steps steps(o);
  ExtractFeatures(steps, given, o.images, db);
  colmap::WriteReconstruction(base, BaseModel(given, group, colmap::ReadDatabaseImages(db)), colmap::ModelFormat::kBinary);

  const std::vector<Pair> pairs = PairsToMatch(given, group, o);
  std::string text;
  for (const auto& [a, b] : pairs) text += a + " " + b + "\n";
  WriteFileAtomically(pairs_path, text);
  if (o.say) o.say(StrCat("matching ", pairs.size(), " pairs (the ", group.size(), " photos of the group with ",
                          "the others, the others with their neighbours in the model)"));
  steps.Run({"matches_importer", "--database_path", db.string(), "--match_list_path", pairs_path.string(),
             "--match_type", "pairs", "--SiftMatching.use_gpu", "0", "--SiftMatching.num_threads", steps.threads},
            "matching", ExhaustiveParser());
  const std::vector<std::string> fixed = {"--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point",
                                          "0", "--Mapper.ba_refine_extra_params", "0", "--Mapper.num_threads", steps.threads};
  const int n = static_cast<int>(given.images.size());
  std::vector<std::string> args = {"point_triangulator", "--database_path", db.string(), "--image_path", o.images.string(),
                                   "--input_path", base.string(), "--output_path", triangulated.string()};
  args.insert(args.end(), fixed.begin(), fixed.end());
  steps.Run(args, "triangulating", MapperParser(n));
  args = {"image_registrator", "--database_path", db.string(), "--input_path", triangulated.string(), "--output_path",
          registered.string()};
  args.insert(args.end(), fixed.begin(), fixed.end());
  steps.Run(args, "registering", MapperParser(n));

  GroupRegistration r;
  r.model = InGivenIds(colmap::ReadReconstruction(registered), given);
  std::set<std::string> names;
  for (const auto& [id, im] : r.model.images) names.insert(im.name);
  for (const std::string& name : group) (names.count(name) ? r.placed : r.left_out).push_back(name);
  return r;
}

}  // namespace perf
