#include "recon_cuda/run/render_views.h"

#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/previous_run.h"
#include "recon_cuda/run/refined_poses.h"
#include "workspace/image_io.h"

namespace perf::recon {

namespace fs = std::filesystem;

fs::path FinalCheckpointPath(const fs::path& workspace) {
  const int last = LastCheckpointLevel(workspace);
  if (last < 0) return {};
  const fs::path newest = CheckpointPath(workspace, last);
  const fs::path record = workspace / "recon" / "recon.json";
  std::error_code ec;
  const auto record_time = fs::last_write_time(record, ec);
  if (ec || record_time < fs::last_write_time(newest, ec) || ec) return newest;
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(record), nullptr, false);
  if (!j.is_object() || !j.contains("final_checkpoint") || !j["final_checkpoint"].is_string()) return newest;
  // Only a level file of this workspace's recon/ (a hand-edited record names nothing else).
  const fs::path named = j["final_checkpoint"].get<std::string>();
  for (int level = 0; level <= last; ++level) {
    if (named == fs::relative(CheckpointPath(workspace, level), workspace) && fs::exists(workspace / named, ec)) {
      return CheckpointPath(workspace, level);
    }
  }
  return newest;
}

LoadedCheckpoint LoadForRendering(const fs::path& workspace, const fs::path& checkpoint, DeviceChoice device,
                                  int threads) {
  LoadedCheckpoint l;
  l.path = checkpoint;
  if (l.path.empty()) {
    RecoverPreviousRun(workspace);  // a reconstruct killed before its first level: the run before it
    l.path = FinalCheckpointPath(workspace);
    if (l.path.empty()) {
      throw IoError((workspace / "recon").string(), "no checkpoint found", "run perf reconstruct on this workspace first");
    }
  }
  l.checkpoint = ReadCheckpoint(l.path);
  l.backend = MakeBackend(device, threads);
  l.backend->SetLevel(LevelProblem{l.checkpoint.shape, GeometryOf(l.checkpoint), nullptr, {}}, 1);  // render-only
  l.backend->Upload(LoadedCheckpoint::kParams, l.checkpoint.params);
  return l;
}

PhotoCorrections CorrectionsOf(const LoadedCheckpoint& l, const Scene& scene) {
  const Checkpoint& c = l.checkpoint;
  if (c.shape.exposures == 0 && c.shape.poses == 0) return {};
  const std::vector<ViewFrustum> train = SplitViews(scene, Split::kTrain);
  for (const auto& [field, count] : {std::pair{"exposures", c.shape.exposures}, std::pair{"poses", c.shape.poses}}) {
    if (count != 0 && static_cast<int>(train.size()) != count) {
      throw InputError(l.path.string(), field, StrCat(count, " photos"),
                       StrCat("scene.json has ", train.size(), " training photos: the workspace was imported again"),
                       "run perf reconstruct again");
    }
  }
  return PhotoCorrections(c.shape, c.params, train, GeometryOf(c));
}

Scene PosedAsCheckpoint(const LoadedCheckpoint& l, const Scene& scene) {
  if (l.checkpoint.shape.poses == 0) return scene;
  return PosedAsRefined(WithRefinedPoses(scene, CorrectionsOf(l, scene)));
}

RenderViewsResult RenderViews(const RenderViewsOptions& o) {
  const Scene scene = ReadScene(o.workspace / "scene.json");
  LoadedCheckpoint loaded = LoadForRendering(o.workspace, o.checkpoint, o.device, o.threads);
  const PhotoCorrections exposures = CorrectionsOf(loaded, scene);
  RenderViewsResult result;
  result.checkpoint = loaded.path;

  std::vector<PosedImage> views;
  for (Split s : {Split::kTrain, Split::kTest, Split::kExcluded}) {  // kAll: the excluded ones too
    if ((s != Split::kTest && o.split == ViewSplit::kTest) || (s != Split::kTrain && o.split == ViewSplit::kTrain)) {
      continue;
    }
    std::vector<PosedImage> part = LoadImages(scene, o.workspace, s);
    for (PosedImage& v : part) {
      if (o.names.empty() || std::find(o.names.begin(), o.names.end(), v.name) != o.names.end()) {
        views.push_back(std::move(v));
      }
    }
  }
  for (const std::string& name : o.names) {
    if (std::none_of(views.begin(), views.end(), [&](const PosedImage& v) { return v.name == name; })) {
      throw InputError("command line", "--view", name, o.split == ViewSplit::kAll ? "no image of that name" : StrCat("no image of that name in the ", o.split == ViewSplit::kTest ? "test" : "train", " split"),
                       "use a name from scene.json's images");
    }
  }

  Backend* backend = loaded.backend.get();
  const fs::path out_dir = o.out_dir.empty() ? o.workspace / "renders" : o.out_dir;
  const auto file_of = [&](const PosedImage& v, const char* suffix) {
    return out_dir / (fs::path(v.name).filename().replace_extension().string() + suffix + ".png");
  };
  // The workspace's inputs (its record), and any file PERF did not write, are never written over:
  // refused before the first render.
  ProtectRecordedInputs(o.workspace);
  for (const PosedImage& v : views) {
    for (const char* suffix : {"", "_opacity"}) {
      if (*suffix != 0 && !o.write_opacity) continue;
      CheckMayReplace(file_of(v, suffix), "a render");
    }
  }
  EnsureWritableDirectory(out_dir);
  int done = 0;
  for (const PosedImage& v : views) {
    const RenderOutput render = RenderAsShot(backend, LoadedCheckpoint::kParams, v, o.min_box_opacity, exposures);
    result.scores.push_back({v.name, Psnr(render, v.image)});
    const fs::path file = file_of(v, "");
    WriteImage(file, ToImage(render), PixelFormat::kUInt8);
    result.files.push_back(file);
    if (o.write_opacity) {
      const fs::path op = file_of(v, "_opacity");
      WriteImage(op, OpacityImage(render), PixelFormat::kUInt16);
      result.files.push_back(op);
    }
    if (o.progress) o.progress(++done, static_cast<int>(views.size()));
  }
  result.mean_psnr = MeanPsnr(result.scores);
  return result;
}

}  // namespace perf::recon
