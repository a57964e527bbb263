#include "export/export.h"

#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <numbers>
#include <set>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/owned_files.h"
#include "common/stopwatch.h"
#include "export/evaluate.h"
#include "export/export_set.h"
#include "export/mesh_simplify.h"
#include "export/mesh_texture.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/run/evaluation.h"
#include "recon_cuda/run/render_views.h"
#include "workspace/image_io.h"

namespace perf::exporter {

namespace fs = std::filesystem;
using recon::LoadedCheckpoint;

namespace {

void Progress(const ExportOptions& o, const std::string& step, int done, int total) {
  if (o.progress) o.progress(step, done, total);
}

// Writes one output into the staging folder (export_set.h), creating its folder, and records it
// relative to the workspace.
class Outputs {
 public:
  Outputs(fs::path staging, ExportResult* result) : staging_(std::move(staging)), result_(result) {}
  fs::path Prepare(const fs::path& relative) {
    const fs::path path = staging_ / relative;
    if (created_.insert(path.parent_path()).second) EnsureWritableDirectory(path.parent_path());
    result_->files.push_back(relative);
    return path;
  }

 private:
  fs::path staging_;
  ExportResult* result_;
  std::set<fs::path> created_;
};

// The photos must all be there, at the size their camera says, before anything is written.
void CheckPhotos(const Scene& scene) {
  for (const SceneImage& im : scene.images) {
    const SceneCamera& cam = scene.camera(im.camera_id);
    if (!fs::exists(im.source_path)) {
      throw IoError(im.source_path, StrCat("the photo of image '", im.name, "' is missing"),
                    "put the photos back where perf import found them, or export without cut-outs (--no-foreground)");
    }
    const ImageInfo info = ReadImageInfo(im.source_path);
    if (info.width != cam.source.width || info.height != cam.source.height) {
      throw InputError(im.source_path, "size", StrCat(info.width, "x", info.height),
                       StrCat("scene.json says camera ", cam.id, "'s photos are ", cam.source.width, "x", cam.source.height),
                       "the photos changed since perf import; re-run perf import and perf reconstruct");
    }
  }
}

// The files of one photo: masks and cut-out. Paths are prepared (folders created) by the caller.
struct MaskFiles {
  fs::path soft, binary, foreground;
};

// Binarises, writes and cuts out one photo (thread-safe: touches only its own files).
double WriteMaskFiles(const ExportOptions& o, const Scene& scene, const SceneImage& im, const Image& soft,
                      const MaskFiles& files) {
  const Image binary = Binarize(soft, o.mask_threshold);
  if (o.masks) {
    WriteImage(files.soft, soft, o.soft_mask_exr ? PixelFormat::kHalf : PixelFormat::kUInt16);
    WriteImage(files.binary, binary, PixelFormat::kUInt8);
  }
  if (o.foreground) {
    ImageInfo info;
    const Image photo = ToRgb(ReadImage(im.source_path, &info), {scene.background.x(), scene.background.y(), scene.background.z()});
    const Image& alpha = o.foreground_soft_alpha ? soft : binary;
    // OpenImageIO takes associated (premultiplied) colour and un-premultiplies for PNG.
    Image rgba(photo.width, photo.height, 4);
    for (size_t p = 0; p < alpha.pixels.size(); ++p) {
      const float a = alpha.pixels[p];
      for (int c = 0; c < 3; ++c) rgba.pixels[4 * p + c] = photo.pixels[3 * p + c] * a;
      rgba.pixels[4 * p + 3] = a;
    }
    const PixelFormat format = info.format == PixelFormat::kUInt8 ? PixelFormat::kUInt8 : PixelFormat::kUInt16;
    WriteImage(files.foreground, rgba, format);
  }
  double in = 0;
  for (float v : binary.pixels) in += v;
  return in / binary.pixels.size();
}

void ExportMasks(const ExportOptions& o, const Scene& scene, LoadedCheckpoint& l, Outputs& out, ExportResult* r) {
  if (o.foreground) CheckPhotos(scene);
  std::map<int, PhotoFrame> frames;
  // A photo whose pose looks wrong (left out on import) gets no mask: the volume seen from a
  // wrong pose does not outline the object in the photo.
  std::vector<const SceneImage*> photos;
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kExcluded) {
      r->no_mask.push_back(im.name);
    } else {
      photos.push_back(&im);
    }
  }
  double coverage = 0;
  int done = 0;
  const int total = static_cast<int>(photos.size());
  // Masks are rendered one photo at a time (the backend uses every core per render) and then
  // encoded in parallel a batch at a time: PNG encoding of full-size photos would otherwise
  // take most of the time.
  constexpr size_t kBatch = 8;
  for (size_t first = 0; first < photos.size(); first += kBatch) {
    const size_t count = std::min(kBatch, photos.size() - first);
    std::vector<Image> soft(count);
    std::vector<MaskFiles> files(count);
    for (size_t k = 0; k < count; ++k) {
      const SceneImage& im = *photos[first + k];
      const SceneCamera& cam = scene.camera(im.camera_id);
      auto it = frames.find(cam.id);
      if (it == frames.end()) it = frames.emplace(cam.id, PhotoFrame::Create(cam)).first;
      soft[k] = RenderPhotoMask(l.backend.get(), LoadedCheckpoint::kParams, cam, im, it->second, o.mask);
      const fs::path name = OutputName(im);
      if (o.masks) {
        files[k].soft = out.Prepare("masks/soft" / fs::path(name).concat(o.soft_mask_exr ? ".exr" : ".png"));
        files[k].binary = out.Prepare("masks/binary" / fs::path(name).concat(".png"));
      }
      if (o.foreground) files[k].foreground = out.Prepare("foreground" / fs::path(name).concat(".png"));
    }
    std::vector<double> cover(count);
    tbb::parallel_for(size_t{0}, count, [&](size_t k) {
      cover[k] = WriteMaskFiles(o, scene, *photos[first + k], soft[k], files[k]);
    });
    for (size_t k = 0; k < count; ++k) {
      coverage += cover[k];
      r->masks += o.masks;
      r->foreground += o.foreground;
      Progress(o, "masks", ++done, total);
    }
  }
  r->mean_mask_coverage = total > 0 ? coverage / total : 0;
}

void ExportRenders(const ExportOptions& o, const Scene& scene, LoadedCheckpoint& l, Outputs& out, ExportResult* r) {
  std::vector<const SceneImage*> test;
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kTest) test.push_back(&im);
  }
  const std::vector<OrbitView> orbit = o.orbit.frames > 0 ? OrbitCameras(scene, o.orbit) : std::vector<OrbitView>{};
  if (o.orbit.follow_capture) r->orbit_arc_degrees = CapturedArc(scene).span * 180 / std::numbers::pi;
  const int total = static_cast<int>(test.size() + orbit.size());
  int done = 0;
  for (const SceneImage* im : test) {
    const SceneCamera& cam = scene.camera(im->camera_id);
    const recon::RenderOutput render = l.backend->Render(LoadedCheckpoint::kParams, recon::ToPinhole(cam, im->world_from_cam),
                                                         cam.width, cam.height, o.min_box_opacity);
    WriteImage(out.Prepare("renders/test" / fs::path(OutputName(*im)).concat(".png")), recon::ToImage(render),
               PixelFormat::kUInt8);
    ++r->renders;
    Progress(o, "renders", ++done, total);
  }
  for (size_t k = 0; k < orbit.size(); ++k) {
    const recon::RenderOutput render =
        l.backend->Render(LoadedCheckpoint::kParams, orbit[k].camera, orbit[k].width, orbit[k].height, o.min_box_opacity);
    char file[32];
    std::snprintf(file, sizeof(file), "frame_%04zu.png", k);
    WriteImage(out.Prepare(fs::path("renders/orbit") / file), recon::ToImage(render), PixelFormat::kUInt8);
    ++r->orbit_frames;
    Progress(o, "renders", ++done, total);
  }
}

// The groups of outputs (export_set.h ExportGroup) this export writes: their old files go.
std::set<std::string> GroupsWritten(const ExportOptions& o) {
  std::set<std::string> groups{"sparse_refined"};
  for (const auto& [on, group] : {std::pair{o.masks, "masks"}, {o.foreground, "foreground"}, {o.volume, "volume"},
                                  {o.mesh, "mesh"}, {o.renders, "renders"}}) {
    if (on) groups.insert(group);
  }
  return groups;
}

// export.json: this export's files and sections, and those of the old manifest's groups that this
// export leaves as they were (still on disk), so that it describes every file there.
nlohmann::json Manifest(const ExportOptions& o, const ExportResult& r, const fs::path& workspace,
                        const nlohmann::json& old) {
  nlohmann::json files = nlohmann::json::array();
  for (const fs::path& f : r.files) files.push_back(f.generic_string());
  const std::set<std::string> groups = GroupsWritten(o);
  for (const fs::path& f : ManifestFiles(old)) {  // kept: an old group this export did not write
    const std::string group = ExportGroup(f);
    std::error_code ec;
    if (!group.empty() && !groups.count(group) && fs::exists(workspace / f, ec)) files.push_back(f.generic_string());
  }
  nlohmann::json j;
  j["format"] = "perf-export";
  j["version"] = 1;
  j["checkpoint"] = fs::relative(r.checkpoint, workspace).generic_string();
  j["colour"] = {{"png", "srgb"}, {"vdb", "linear"}, {"glb", "linear"}, {"ply", "srgb"}, {"obj", "srgb"}};
  j["masks"] = {{"count", r.masks},
                {"threshold", o.mask_threshold},
                {"soft_format", o.soft_mask_exr ? "exr (half)" : "png (16-bit)"},
                {"mean_coverage", r.mean_mask_coverage},
                {"foreground_cutouts", r.foreground},
                {"foreground_alpha", o.foreground_soft_alpha ? "soft" : "binary"},
                {"not_written", r.no_mask}};
  if (o.volume) {
    j["volume"] = {{"file", "volume.vdb"},
                   {"density_grid", r.vdb.density_grid},
                   {"colour_grid", r.vdb.colour_grid},
                   {"active_voxels", r.vdb.active_voxels},
                   {"total_voxels", r.vdb.total_voxels},
                   {"voxel_size", {r.vdb.voxel_size[0], r.vdb.voxel_size[1], r.vdb.voxel_size[2]}},
                   {"bytes", r.vdb.file_bytes},
                   {"min_cell_opacity", o.vdb.min_cell_opacity},
                   {"half_float", o.vdb.half_float}};
  }
  if (o.mesh) {
    j["mesh"] = {{"files", r.texture_size[0] > 0 ? nlohmann::json{"mesh.ply", "mesh.obj", "mesh.mtl", "mesh.png", "mesh.glb"}
                                                : nlohmann::json{"mesh.ply", "mesh.obj", "mesh.glb"}},
                 {"texture", {{"file", r.texture_size[0] > 0 ? "mesh.png" : ""},
                              {"width", r.texture_size[0]},
                              {"height", r.texture_size[1]}}},
                 {"vertices", r.mesh_vertices},
                 {"triangles", r.mesh_triangles},
                 {"components_found", r.mesh_components_found},
                 {"components_kept", r.mesh_components_kept},
                 {"triangles_extracted", r.mesh_triangles_extracted},  // before simplification
                 {"max_triangles", o.mesh_triangles},
                 {"min_component_fraction", o.mesh_options.min_component_fraction}};
    j["mesh"].update(r.iso.ToJson());
  }
  j["renders"] = {{"test", r.renders},
                  {"orbit", r.orbit_frames},
                  {"orbit_arc_degrees", r.orbit_arc_degrees},  // 360: a full turn; less: the captured arc and back
                  {"min_box_opacity", o.min_box_opacity}};
  if (!r.refined_model.dir.empty() || !r.refined_model.not_written.empty()) {
    j["refined_model"] = {{"dir", r.refined_model.dir.generic_string()},
                          {"images_moved", r.refined_model.moved},
                          {"format", "COLMAP binary (cameras.bin, images.bin, points3D.bin)"},
                          {"not_written", r.refined_model.not_written}};
  }
  j["seconds"] = r.seconds;
  j["files"] = files;
  for (const auto& [group, section] : {std::pair{"volume", "volume"}, {"mesh", "mesh"}, {"renders", "renders"}}) {
    if (!groups.count(group) && old.is_object() && old.contains(section)) j[section] = old[section];
  }
  if (!o.masks && !o.foreground && old.is_object() && old.contains("masks")) j["masks"] = old["masks"];
  return j;
}

// The mesh at the level its silhouettes choose (mesh_iso.h), simplified to the budget, with its
// baked texture: mesh.ply (vertex colours), mesh.obj + mesh.mtl + mesh.png (texture and vertex
// colours), mesh.glb (the texture embedded).
void ExportMesh(const ExportOptions& o, const Scene& scene, LoadedCheckpoint& l, Outputs& out, ExportResult* r) {
  Progress(o, "mesh", 0, 4);
  Mesh mesh;
  const Silhouettes views = RenderSilhouettes(l, scene, o.mask_threshold);
  r->iso = ChooseIsoAndMesh(l.checkpoint, o.mesh_options, o.auto_iso, views, &mesh);
  r->mesh_triangles_extracted = static_cast<int64_t>(mesh.triangles.size());
  if (SimplifyMesh(&mesh, o.mesh_triangles).triangles_after < r->mesh_triangles_extracted) {
    r->iso.silhouette_iou = SilhouetteIou(mesh, views);  // the mesh as written
  }
  r->mesh_vertices = static_cast<int64_t>(mesh.positions.size());
  r->mesh_triangles = static_cast<int64_t>(mesh.triangles.size());
  r->mesh_components_found = mesh.components_found;
  r->mesh_components_kept = mesh.components_kept;
  const TexturedMesh textured = BakeTexture(mesh, ColourSampler(l.checkpoint));
  r->texture_size = {textured.width, textured.height};
  Progress(o, "mesh", 1, 4);
  WritePly(out.Prepare("mesh.ply"), mesh);
  Progress(o, "mesh", 2, 4);
  const std::string png = TexturePng(textured);
  if (textured.width > 0) {
    WriteStreamAtomically(out.Prepare("mesh.obj"), [&](std::ostream& s) { WriteTexturedObj(s, textured, "mesh.mtl"); });
    WriteStreamAtomically(out.Prepare("mesh.mtl"), [&](std::ostream& s) { WriteMtl(s, "mesh.png"); });
    WriteFileAtomically(out.Prepare("mesh.png"), png);
  } else {
    WriteObj(out.Prepare("mesh.obj"), mesh);  // an empty mesh has no texture
  }
  Progress(o, "mesh", 3, 4);
  WriteStreamAtomically(out.Prepare("mesh.glb"), [&](std::ostream& s) { WriteGlb(s, mesh, textured.uvs, png); });
  Progress(o, "mesh", 4, 4);
}

// Every output into `staging`, then export.json, then the set committed (export_set.h).
void WriteSet(const ExportOptions& o, const Scene& scene, LoadedCheckpoint& l, const fs::path& staging,
              const nlohmann::json& old_manifest, WallClock::time_point start, ExportResult* r) {
  Outputs out(staging, r);
  if (o.masks || o.foreground) ExportMasks(o, scene, l, out, r);
  if (o.volume) {
    Progress(o, "volume", 0, 1);
    r->vdb = WriteVdb(l.checkpoint, out.Prepare("volume.vdb"), o.vdb);
    Progress(o, "volume", 1, 1);
  }
  if (o.mesh) ExportMesh(o, scene, l, out, r);
  if (o.renders) ExportRenders(o, scene, l, out, r);
  if (l.checkpoint.shape.poses != 0) {  // without refined poses an old sparse_refined/ goes (stale)
    r->refined_model = WriteRefinedModel(scene, staging);
    if (!r->refined_model.dir.empty()) {
      for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) r->files.push_back(r->refined_model.dir / f);
    }
  }
  r->seconds = SecondsSince(start);
  WriteFileAtomically(staging / "export.json", Manifest(o, *r, o.workspace, old_manifest).dump(2) + "\n");
  std::vector<fs::path> set = r->files;
  set.push_back("export.json");
  CommitStagedExport(o.workspace, set, GroupsWritten(o), old_manifest);
}

}  // namespace

fs::path OutputName(const SceneImage& image) {
  fs::path rel = fs::path(image.path).lexically_relative("images");
  if (rel.empty() || *rel.begin() == "..") rel = fs::path(image.path).filename();
  return rel.replace_extension();
}

ExportResult RunExport(const ExportOptions& o) {
  const auto start = WallClock::now();
  if (!(o.mask_threshold > 0 && o.mask_threshold <= 1)) {
    throw InputError("command line", "--mask-threshold", StrCat(o.mask_threshold), "must be in (0, 1]");
  }
  if (!(o.mask.render_scale > 0 && o.mask.render_scale <= 8)) {
    throw InputError("command line", "--mask-render-scale", StrCat(o.mask.render_scale), "must be in (0, 8]");
  }
  if (!o.auto_iso && !(o.mesh_options.iso_opacity > 0 && o.mesh_options.iso_opacity < 1)) {
    throw InputError("command line", "--iso", StrCat(o.mesh_options.iso_opacity), "must be in (0, 1)",
                     "an opacity across one voxel; 0.5 is a common choice");
  }
  if (!(o.mesh_options.min_component_fraction >= 0 && o.mesh_options.min_component_fraction <= 1)) {
    throw InputError("command line", "--min-component", StrCat(o.mesh_options.min_component_fraction),
                     "must be in [0, 1]");
  }
  if (!(o.vdb.min_cell_opacity >= 0 && o.vdb.min_cell_opacity < 1)) {
    throw InputError("command line", "--vdb-min-opacity", StrCat(o.vdb.min_cell_opacity), "must be in [0, 1)");
  }
  if (o.mesh_triangles < 0) {
    throw InputError("command line", "--mesh-triangles", StrCat(o.mesh_triangles), "must be >= 0 (0: no limit)");
  }
  if (o.orbit.frames < 0) throw InputError("command line", "--orbit-frames", StrCat(o.orbit.frames), "must be >= 0");
  if (o.renders && o.orbit.frames > 0) CheckOrbitOptions(o.orbit);
  const Scene imported = ReadScene(o.workspace / "scene.json");
  for (const SceneImage& im : imported.images) ProtectInput(im.source_path);  // the user's photos
  LoadedCheckpoint l = recon::LoadForRendering(o.workspace, o.checkpoint, o.device, o.threads);
  // Masks, cut-outs, renders and the mesh's views see the cameras as the checkpoint refined them.
  const Scene scene = recon::PosedAsCheckpoint(l, imported);
  ExportResult r;
  r.checkpoint = l.path;
  // Every output folder is checked before any work, so a bad one fails fast and writes nothing.
  EnsureWritableDirectory(o.workspace);
  if (o.masks) {
    EnsureWritableDirectory(o.workspace / "masks" / "soft");
    EnsureWritableDirectory(o.workspace / "masks" / "binary");
  }
  if (o.foreground) EnsureWritableDirectory(o.workspace / "foreground");
  if (o.renders) {
    EnsureWritableDirectory(o.workspace / "renders" / "test");
    if (o.orbit.frames > 0) EnsureWritableDirectory(o.workspace / "renders" / "orbit");
  }
  const nlohmann::json old_manifest = ReadOldManifest(o.workspace);
  const fs::path staging = StartStagedExport(o.workspace);
  try {
    WriteSet(o, scene, l, staging, old_manifest, start, &r);
  } catch (...) {
    try {
      FinishStagedExport(o.workspace);  // not committed: the staged files go (a commit under way is finished)
    } catch (const Error&) {
      // Left for the next command that locks the workspace.
    }
    throw;
  }
  return r;
}

double EstimateExportAndEvalSeconds(recon::Backend* backend, recon::VecId params, const Scene& scene,
                                    const ExportOptions& o, bool pose_fit) {
  const SceneImage* photo = nullptr;
  int photos = 0;
  double test_pixels = 0;
  std::set<int> cameras;
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kExcluded) continue;
    ++photos;
    if (photo == nullptr) photo = &im;
    cameras.insert(im.camera_id);
    const SceneCamera& cam = scene.camera(im.camera_id);
    if (im.split == Split::kTest) test_pixels += static_cast<double>(cam.width) * cam.height;
  }
  if (photo == nullptr) return 0;
  const SceneCamera& cam = scene.camera(photo->camera_id);
  // The photo's mask (and its camera's frame, made once per camera).
  auto t0 = WallClock::now();
  const PhotoFrame frame = PhotoFrame::Create(cam);
  const double frame_seconds = SecondsSince(t0);
  t0 = WallClock::now();
  const Image soft = RenderPhotoMask(backend, params, cam, *photo, frame, o.mask);
  const double mask_seconds = SecondsSince(t0);
  // Its files, written where nothing of the user's is, then removed.
  const fs::path probe = PrivateFolder(o.workspace) / "probe";
  EnsureWritableDirectory(probe);
  t0 = WallClock::now();
  WriteMaskFiles(o, scene, *photo, soft, {probe / "soft.png", probe / "binary.png", probe / "foreground.png"});
  const double files_seconds = SecondsSince(t0);
  RemoveOwnedTree(probe);
  // Its render at the workspace's size, for the other renders and eval's scores.
  t0 = WallClock::now();
  backend->Render(params, recon::ToPinhole(cam, photo->world_from_cam), cam.width, cam.height, o.min_box_opacity);
  const double per_pixel = SecondsSince(t0) / std::max(1.0, static_cast<double>(cam.width) * cam.height);
  double orbit_pixels = 0;
  if (o.renders && o.orbit.frames > 0) {
    for (const OrbitView& v : OrbitCameras(scene, o.orbit)) orbit_pixels += static_cast<double>(v.width) * v.height;
  }
  // Masks are rendered one photo at a time and written in parallel batches of 8 (ExportMasks).
  const double writers = std::clamp<double>(tbb::this_task_arena::max_concurrency(), 1, 8);
  const double masks = static_cast<double>(cameras.size()) * frame_seconds + photos * (mask_seconds + files_seconds / writers);
  const double renders = (o.renders ? test_pixels + orbit_pixels : 0) * per_pixel;
  // eval: each held-out view rendered and scored (about twice its render); the pose fit's
  // iterations on the views at most kPoseFitSide across, each about kPoseFitRenders renders.
  constexpr double kPoseFitRenders = 16;  // the example: 2.9 s for 5 views of 100 x 67
  const double factor = PoseFitDownscale(cam.width, cam.height, kPoseFitSide);
  const double fit = pose_fit ? kPoseFitIterations * kPoseFitRenders * test_pixels / (factor * factor) * per_pixel : 0;
  return masks + renders + 2 * test_pixels * per_pixel + fit;
}

}  // namespace perf::exporter
