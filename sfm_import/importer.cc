#include "sfm_import/importer.h"

#include <tbb/global_control.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/inputs.h"
#include "sfm_import/bad_poses.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_model.h"
#include "sfm_import/colmap_pose.h"
#include "sfm_import/ghost_groups.h"
#include "workspace/image_io.h"
#include "sfm_import/import_images.h"
#include "sfm_import/nerf_reader.h"
#include "sfm_import/undistort.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

using namespace import_detail;

constexpr const char* kCommandLine = "command line";

// The size after --downscale / --max-size.
void OutputSize(const ImportOptions& o, int w, int h, int* ow, int* oh) {
  double s = 1.0 / o.downscale;
  if (o.max_size > 0) s = std::min(1.0, static_cast<double>(o.max_size) / std::max(w, h));
  *ow = std::max(1, static_cast<int>(std::lround(w * s)));
  *oh = std::max(1, static_cast<int>(std::lround(h * s)));
}

// All image files under `dir`, as '/'-separated paths relative to it (COLMAP's image names).
std::set<std::string> ListImages(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& e : fs::recursive_directory_iterator(dir, fs::directory_options::skip_permission_denied)) {
    if (e.is_regular_file() && HasImageExtension(e.path())) {
      // Lexically: fs::relative would resolve a symlinked photo to its target's path.
      names.insert(e.path().lexically_relative(dir).generic_string());
    }
  }
  return names;
}

// Every N-th image in the given order is held out: COLMAP images sorted by name (the mip-NeRF
// 360 convention), NeRF frames in the json's order (r_0, r_8, r_16, ...).
// An excluded image (a bad pose) keeps its place in the count, so that the held-out views are
// the same ones with or without --keep-bad-poses.
void AssignSplit(std::vector<SceneImage>* images, int holdout) {
  for (size_t i = 0; i < images->size(); ++i) {
    if ((*images)[i].split == Split::kExcluded) continue;
    (*images)[i].split = holdout > 0 && i % holdout == 0 ? Split::kTest : Split::kTrain;
  }
}

// The cameras that place the box and shells: not those left out (a wrong pose far away would
// push the outer shell out to it).
std::vector<BoundsCamera> BoundsCameras(const Scene& scene) {
  std::vector<BoundsCamera> out;
  for (const auto& im : scene.images) {
    if (im.split == Split::kExcluded) continue;
    const SceneCamera& c = scene.camera(im.camera_id);
    out.push_back({im.world_from_cam, c.fx, c.fy, c.cx, c.cy, c.width, c.height});
  }
  return out;
}

void PlaceBoundsAndShells(const ImportOptions& o, const std::vector<BoundsPoint>& points,
                          const std::string& source, ImportResult* r) {
  BoundsOptions bo = o.bounds;
  if (o.box_axis_aligned) bo.align_to_up = false;
  const bool manual_box = o.box_center && o.box_size;
  if (!manual_box) {
    r->bounds = EstimateBounds(BoundsCameras(r->scene), points, bo, source);
  } else {
    r->bounds.box.rotation = Eigen::Matrix3d::Identity();
  }
  SceneBox& box = r->bounds.box;
  if (o.box_center) box.center = *o.box_center;
  if (o.box_size) box.size = *o.box_size;
  if (o.box_center || o.box_size) box.method = manual_box ? "given on the command line" : box.method + " (partly overridden)";
  if (manual_box || o.box_center || o.box_size) {
    // Shells around the new box: enclosing the cameras, at the points' distances from it.
    double camera_radius = 0;
    for (const auto& im : r->scene.images) {
      if (im.split != Split::kExcluded) camera_radius = std::max(camera_radius, (im.world_from_cam.col(3) - box.center).norm());
    }
    std::vector<double> distances;
    for (const auto& p : points) {
      if (IsRobustPoint(p, bo)) distances.push_back((p.xyz - box.center).norm());
    }
    r->bounds.shells = PlaceShells(box, camera_radius, std::move(distances), bo);
  }
  if (o.shell_radii) {
    r->bounds.shells.center = box.center;
    r->bounds.shells.radii = *o.shell_radii;
  }
  const double half_diag = 0.5 * box.size.norm();
  if (r->bounds.shells.radii.front() <= half_diag) {
    r->warnings.push_back(StrCat("the innermost shell (radius ", r->bounds.shells.radii.front(), ") cuts the box (half diagonal ",
                                 half_diag, "): a ray leaving the box through a corner can pass beyond the shell and see "
                                 "no background; give --shell-radii a first radius above ", half_diag));
  }
  r->scene.box = box;
  r->scene.shells = r->bounds.shells;
}

// ---- COLMAP ----

// The photos of a COLMAP model: their folder, the image files in it and, for the model's photos
// found there, what their headers say, by camera.
struct ColmapPhotos {
  fs::path dir;                   // --images, or <model>/../../images
  std::set<std::string> on_disk;  // image files under `dir` (ListImages)
  std::map<uint32_t, std::vector<std::pair<fs::path, ImageInfo>>> by_camera;
  PixelFormat format = PixelFormat::kUInt8;  // the photos' pixel format (the last one read)
  LargestPhoto largest;                      // the largest photo decoded
};

// The model's photos whose pose looks wrong (bad_poses.h): name -> why, each with a warning.
std::map<std::string, std::string> WarnBadPoses(const ImportOptions& o, const colmap::Reconstruction& rec,
                                                ImportResult* r) {
  std::map<std::string, std::string> bad_poses;  // image name -> why
  for (const BadPose& b : FindBadPoses(rec)) {
    bad_poses[b.name] = StrCat("pose looks wrong: ", b.Describe());
    r->warnings.push_back(StrCat("the pose of ", b.name, " looks wrong (", b.Why(),
                                 "): COLMAP may have registered it in the wrong place; ",
                                 o.keep_bad_poses ? "kept (--keep-bad-poses)"
                                                  : "left out of training and scoring (--keep-bad-poses keeps it)"));
  }
  return bad_poses;
}

// The photos' folder and its image files; throws InputError when it is no folder or holds none.
ColmapPhotos ListColmapPhotos(const ImportOptions& o, const fs::path& model_dir) {
  ColmapPhotos photos;
  photos.dir = o.images_dir.empty() ? DefaultColmapImages(model_dir) : o.images_dir;
  if (!fs::is_directory(photos.dir)) {
    throw InputError(kCommandLine, "--images", photos.dir.string(), "not a folder",
                     "pass the folder of photos the COLMAP model was made from");
  }
  photos.on_disk = ListImages(photos.dir);
  if (photos.on_disk.empty()) {
    throw InputError(photos.dir.string(), "", "", "no image files found (JPEG, PNG, TIFF, EXR...)",
                     "pass the folder of photos the COLMAP model was made from with --images");
  }
  return photos;
}

// The model's images missing on disk are an error, or with --skip-missing a warning (unless
// all are missing); photos on disk that the model lacks are a warning.
void CheckModelAgainstDisk(const ImportOptions& o, const colmap::Reconstruction& rec, const ColmapPhotos& photos,
                           ImportResult* r) {
  std::vector<std::string> missing;
  std::set<std::string> in_model;
  for (const auto& [id, im] : rec.images) {
    in_model.insert(im.name);
    if (!photos.on_disk.count(im.name)) missing.push_back(im.name);
  }
  if (!missing.empty()) {
    std::string list;
    for (size_t i = 0; i < missing.size() && i < 5; ++i) list += (i ? ", " : "") + missing[i];
    if (missing.size() > 5) list += ", ...";
    if (!o.skip_missing || missing.size() == rec.images.size()) {
      throw InputError(photos.dir.string(), "image", missing.front(),
                       StrCat(missing.size(), " of ", rec.images.size(),
                              " images in the model are not in the folder: ", list),
                       o.skip_missing ? "none of the model's images is there: check --images"
                                      : "point --images at the folder COLMAP used, or pass --skip-missing to import the others");
    }
    r->warnings.push_back(StrCat("skipped ", missing.size(), " images missing on disk: ", list));
  }
  std::vector<std::string> extra;
  for (const auto& n : photos.on_disk) {
    if (!in_model.count(n)) extra.push_back(n);
  }
  if (!extra.empty()) {
    r->warnings.push_back(StrCat(extra.size(), " images in ", photos.dir.string(), " are not in the model (not registered by "
                                 "COLMAP?) and are ignored, e.g. ", extra.front(), "; perf sfm --force maps every photo again"));
  }
}

// Reads the headers of the model's photos on disk, each protected as an input, into `photos`.
void ReadPhotoHeaders(const colmap::Reconstruction& rec, ColmapPhotos* photos) {
  for (const auto& [id, im] : rec.images) {
    if (!photos->on_disk.count(im.name)) continue;
    const fs::path p = photos->dir / im.name;
    ProtectInput(p);
    const ImageInfo info = ReadImageInfo(p);
    photos->format = info.format;
    photos->largest.Consider(p, info);
    photos->by_camera[im.camera_id].emplace_back(p, info);
  }
}

// Checks each image's size against its camera: equal, or an exact integer downscale
// (mip-NeRF 360's images_4/), which scales the intrinsics.
void CheckCameraSizes(const colmap::Reconstruction& rec, const ColmapPhotos& photos) {
  for (const auto& [cam_id, infos] : photos.by_camera) {
    CheckOneSize(infos, StrCat("camera ", cam_id), "images of one camera must all have one size");
    const colmap::Camera& cam = rec.cameras.at(cam_id);
    const auto& [p, info] = infos.front();
    if (static_cast<uint64_t>(info.width) == cam.width && static_cast<uint64_t>(info.height) == cam.height) continue;
    bool integer_downscale = false;
    for (int k = 2; k <= 64 && !integer_downscale; ++k) {
      integer_downscale = std::abs(static_cast<double>(cam.width) / k - info.width) < 1.0 &&
                          std::abs(static_cast<double>(cam.height) / k - info.height) < 1.0;
    }
    if (!integer_downscale) {
      throw InputError(p.string(), "size", StrCat(info.width, "x", info.height),
                       StrCat("camera ", cam_id, " in the model is ", cam.width, "x", cam.height,
                              ", and this is neither that size nor an integer downscale of it"),
                       "pass the images the model was made from (or a folder like images_4/ that is an exact downscale)");
    }
  }
}

// Scales a camera (of `model`) to the size of its photos on disk.
void ScaleToSize(const colmap::CameraModelInfo& model, const ImageInfo& size, colmap::Camera* cam) {
  const double sx = static_cast<double>(size.width) / cam->width;
  const double sy = static_cast<double>(size.height) / cam->height;
  if (sx != 1.0 || sy != 1.0) {
    // COLMAP's pixel convention (corner at 0) makes scaling f and c by the size ratio exact.
    if (colmap::NumFocalParams(model.id) == 3) {
      cam->params[0] *= 0.5 * (sx + sy);
      cam->params[1] *= sx;
      cam->params[2] *= sy;
    } else {
      cam->params[0] *= sx;
      cam->params[1] *= sy;
      cam->params[2] *= sx;
      cam->params[3] *= sy;
    }
    cam->width = static_cast<uint64_t>(size.width);
    cam->height = static_cast<uint64_t>(size.height);
  }
}

// Cameras: scale to the size on disk, undistort to pinhole, then apply --downscale; returns their undistorters.
std::map<uint32_t, Undistorter> AddCameras(const ImportOptions& o, const colmap::Reconstruction& rec,
                                           const fs::path& model_dir, const ColmapPhotos& photos, ImportResult* r) {
  std::map<uint32_t, Undistorter> undistorters;
  for (const auto& [cam_id, infos] : photos.by_camera) {  // one size each (CheckOneSize)
    colmap::Camera cam = rec.cameras.at(cam_id);
    const auto* model = colmap::FindCameraModel(cam.model_id);
    ScaleToSize(*model, infos.front().second, &cam);
    Undistorter u = Undistorter::Create(cam, StrCat((model_dir / "cameras").string(), " camera ", cam_id));
    const PinholeIntrinsics& pin = u.pinhole();
    SceneCamera sc;
    sc.id = static_cast<int>(cam_id);
    OutputSize(o, pin.width, pin.height, &sc.width, &sc.height);
    const double ox = static_cast<double>(sc.width) / pin.width, oy = static_cast<double>(sc.height) / pin.height;
    sc.fx = pin.fx * ox;
    sc.fy = pin.fy * oy;
    sc.cx = pin.cx * ox;
    sc.cy = pin.cy * oy;
    sc.source = {std::string(model->name), cam.params, static_cast<int>(cam.width), static_cast<int>(cam.height)};
    r->scene.cameras.push_back(sc);
    undistorters.emplace(cam_id, std::move(u));
  }
  return undistorters;
}

// The scene's images, one per model photo on disk (those with a bad pose excluded unless
// --keep-bad-poses), in the model's order; returns the job that writes each.
std::vector<ImageJob> AddImages(const ImportOptions& o, const colmap::Reconstruction& rec, const ColmapPhotos& photos,
                                const std::map<std::string, std::string>& bad_poses,
                                const std::map<uint32_t, Undistorter>& undistorters, ImportResult* r) {
  const std::string ext = OutputExtension(photos.format);
  std::vector<ImageJob> jobs;
  std::set<std::string> taken;
  for (const auto& [id, im] : rec.images) {
    if (!photos.on_disk.count(im.name)) continue;
    SceneImage si;
    si.name = im.name;
    si.path = ClaimOutputName("images", im.name, ext, &taken);
    si.source_path = fs::absolute(photos.dir / im.name).lexically_normal().string();
    si.camera_id = static_cast<int>(im.camera_id);
    si.world_from_cam = WorldFromCam(im);
    if (!o.keep_bad_poses && bad_poses.count(im.name)) {
      si.split = Split::kExcluded;
      si.excluded_because = bad_poses.at(im.name);
    }
    const SceneCamera& sc = r->scene.camera(si.camera_id);
    jobs.push_back({photos.dir / im.name, si.path, "", &undistorters.at(im.camera_id), sc.width, sc.height});
    r->scene.images.push_back(std::move(si));
  }
  return jobs;
}

// A COLMAP model and its photos, in the steps above; the scene's images end sorted by name.
void ImportColmap(const ImportOptions& o, ImportResult* r) {
  const fs::path model_dir = o.colmap_dir;
  const colmap::ModelFormat format = colmap::DetectModelFormat(model_dir);
  const colmap::Reconstruction rec = colmap::ReadReconstruction(model_dir);
  const std::map<std::string, std::string> bad_poses = WarnBadPoses(o, rec, r);
  std::error_code ec;
  for (fs::directory_iterator it(model_dir, ec), end; !ec && it != end; it.increment(ec)) ProtectInput(it->path());

  ColmapPhotos photos = ListColmapPhotos(o, model_dir);
  CheckModelAgainstDisk(o, rec, photos, r);
  ReadPhotoHeaders(rec, &photos);
  CheckCameraSizes(rec, photos);
  const std::map<uint32_t, Undistorter> undistorters = AddCameras(o, rec, model_dir, photos, r);
  const std::vector<ImageJob> jobs = AddImages(o, rec, photos, bad_poses, undistorters, r);

  std::sort(r->scene.images.begin(), r->scene.images.end(),
            [](const SceneImage& a, const SceneImage& b) { return a.name < b.name; });
  r->scene.source = {"colmap", RecordedPath(model_dir), RecordedPath(photos.dir),
                     format == colmap::ModelFormat::kBinary ? "binary" : "text", o.downscale, o.max_size};
  PlaceBoundsAndShells(o, BoundsPoints(rec), model_dir.string(), r);
  for (std::string& w : MarkGhostGroups(rec, bad_poses, &r->scene)) r->warnings.push_back(std::move(w));
  MarkTurnUnknown(o.turn_unknown, &r->scene);
  EnsureWritableDirectory(o.workspace / "images");
  RunJobs(jobs, o, photos.largest);
}

// ---- NeRF json ----

void ImportNerf(const ImportOptions& o, ImportResult* r) {
  const NerfTransforms t = ReadNerfTransforms(o.nerf_json);
  const std::string source = o.nerf_json.string();
  // All frames share one camera; check the sizes agree.
  std::vector<std::pair<fs::path, ImageInfo>> infos;
  PixelFormat fmt = PixelFormat::kUInt8;
  bool any_alpha = false;
  LargestPhoto largest;
  ProtectInput(o.nerf_json);
  for (const auto& frame : t.frames) {
    ProtectInput(frame.image_path);
    const ImageInfo info = ReadImageInfo(frame.image_path);
    fmt = info.format;
    any_alpha = any_alpha || info.channels == 2 || info.channels == 4;
    largest.Consider(frame.image_path, info);
    infos.emplace_back(frame.image_path, info);
  }
  PERF_CHECK(!infos.empty());  // ReadNerfTransforms refuses a json without frames
  CheckOneSize(infos, source, "all frames of a transforms.json must have one size");
  const ImageInfo* first = &infos.front().second;
  SceneCamera sc;
  sc.id = 1;
  double fx, fy, cx, cy;
  t.Intrinsics(first->width, first->height, source, &fx, &fy, &cx, &cy);
  sc.source = {"PINHOLE", {fx, fy, cx, cy}, first->width, first->height};
  OutputSize(o, first->width, first->height, &sc.width, &sc.height);
  const double sx = static_cast<double>(sc.width) / first->width, sy = static_cast<double>(sc.height) / first->height;
  sc.fx = fx * sx;
  sc.fy = fy * sy;
  sc.cx = cx * sx;
  sc.cy = cy * sy;
  r->scene.cameras.push_back(sc);

  const fs::path base = fs::absolute(o.nerf_json).parent_path();  // as the frames: a relative json too
  const std::string ext = OutputExtension(fmt);
  std::vector<ImageJob> jobs;
  std::set<std::string> names, taken, taken_alpha;
  for (const auto& f : t.frames) {
    SceneImage si;
    // Lexically: fs::relative would resolve symlinks. A path outside the json's folder keeps
    // its ".." here; WorkspaceSafeName keeps the workspace file inside the workspace.
    si.name = fs::absolute(f.image_path).lexically_normal().lexically_relative(base.lexically_normal()).generic_string();
    if (si.name.empty()) si.name = f.image_path.filename().generic_string();
    if (!names.insert(si.name).second) {
      throw InputError(source, "frames.file_path", f.file_path, "listed twice");
    }
    si.path = ClaimOutputName("images", si.name, ext, &taken);
    if (any_alpha) si.alpha_path = ClaimOutputName("alpha", si.name, ".png", &taken_alpha);
    si.source_path = fs::absolute(f.image_path).lexically_normal().string();
    si.camera_id = sc.id;
    si.world_from_cam = f.world_from_cam;
    jobs.push_back({f.image_path, si.path, si.alpha_path, nullptr, sc.width, sc.height});
    r->scene.images.push_back(std::move(si));
  }
  r->scene.source = {"nerf", RecordedPath(o.nerf_json), RecordedPath(base), "json", o.downscale, o.max_size};
  ImportOptions no = o;
  no.bounds.align_to_up = false;  // the json's world frame is meaningful: keep its axes
  PlaceBoundsAndShells(no, {}, source, r);
  EnsureWritableDirectory(o.workspace / "images");
  if (any_alpha) EnsureWritableDirectory(o.workspace / "alpha");
  RunJobs(jobs, o, largest);
}

}  // namespace

fs::path DefaultColmapImages(const fs::path& model_dir) { return model_dir.parent_path().parent_path() / "images"; }

void ImportOptions::Check() const {
  const bool colmap = !colmap_dir.empty(), nerf = !nerf_json.empty();
  if (colmap == nerf) {
    throw InputError(kCommandLine, "--colmap/--nerf", "", colmap ? "both given" : "neither given",
                     "pass either --colmap SPARSE_DIR --images DIR, or --nerf transforms.json");
  }
  if (nerf && !images_dir.empty()) {
    throw InputError(kCommandLine, "--images", images_dir.string(),
                     "not used with --nerf (image paths come from the json)");
  }
  if (workspace.empty()) throw InputError(kCommandLine, "--workspace", "", "missing", "pass the output folder");
  if (downscale < 1) throw InputError(kCommandLine, "--downscale", std::to_string(downscale), "must be >= 1");
  if (max_size < 0) throw InputError(kCommandLine, "--max-size", std::to_string(max_size), "must be >= 0");
  if (max_size > 0 && downscale != 1) {
    throw InputError(kCommandLine, "--max-size", std::to_string(max_size), "cannot be combined with --downscale");
  }
  if (holdout < 0 || holdout == 1) {
    throw InputError(kCommandLine, "--holdout", std::to_string(holdout),
                     "must be 0 (no test views) or >= 2 (every N-th view held out)");
  }
  if ((background.array() < 0).any() || (background.array() > 1).any()) {
    throw InputError(kCommandLine, "--background", "", "colour components must be in [0, 1]");
  }
  // World units must survive the reconstruction's 32-bit floats with room for its arithmetic.
  constexpr double kMinLength = 1e-6, kMaxLength = 1e6;
  const auto list = [](const Eigen::Vector3d& v) { return StrCat(v.x(), ",", v.y(), ",", v.z()); };
  if (box_size && !((box_size->array() >= kMinLength).all() && (box_size->array() <= kMaxLength).all())) {
    throw InputError(kCommandLine, "--box-size", list(*box_size), "box sides must be between 1e-6 and 1e6 world units",
                     "give the sides in the model's units (import without --box-size prints the automatic box)");
  }
  if (box_center && !(box_center->array().abs() <= kMaxLength).all()) {
    throw InputError(kCommandLine, "--box-center", list(*box_center), "must be finite and within 1e6 world units of the origin");
  }
  if (shell_radii) {
    double prev = 0;
    for (double v : *shell_radii) {
      if (!(v > prev)) {
        throw InputError(kCommandLine, "--shell-radii", std::to_string(v), "radii must be positive and strictly increasing");
      }
      prev = v;
    }
    if (shell_radii->empty()) throw InputError(kCommandLine, "--shell-radii", "", "empty");
    if (shell_radii->size() > kMaxSceneShells || shell_radii->back() > 1e9) {
      throw InputError(kCommandLine, "--shell-radii", StrCat(shell_radii->size(), " radii up to ", shell_radii->back()),
                       StrCat("at most ", kMaxSceneShells, " radii, each at most 1e9 world units"));
    }
  }
  if (bounds.num_shells < 1 || bounds.num_shells > kMaxSceneShells) {
    throw InputError(kCommandLine, "--shells", std::to_string(bounds.num_shells),
                     StrCat("must be 1 to ", kMaxSceneShells, " (the reconstruction's limit)"));
  }
}

ImportResult RunImport(const ImportOptions& o) {
  o.Check();
  const auto start = std::chrono::steady_clock::now();
  EnsureWritableDirectory(o.workspace);
  std::unique_ptr<tbb::global_control> threads;
  if (o.num_threads > 0) {
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, o.num_threads);
  }
  ImportResult r;
  r.scene.background = o.background;
  if (!o.colmap_dir.empty()) {
    ImportColmap(o, &r);
  } else {
    ImportNerf(o, &r);
  }
  AssignSplit(&r.scene.images, o.holdout);
  WriteInputRecord(o.workspace);  // later commands protect the inputs too (common/inputs.h)
  // scene.json last: a workspace with a scene.json has all of its images.
  WriteScene(o.workspace / "scene.json", r.scene);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

std::string ImportSummary(const ImportResult& r) {
  const Scene& s = r.scene;
  int count[3] = {0, 0, 0};
  for (const auto& im : s.images) ++count[static_cast<int>(im.split)];
  std::ostringstream out;
  out.precision(4);
  out << "imported " << s.images.size() << " images (" << count[0] << " train, " << count[1] << " test"
      << (count[2] ? StrCat(", ", count[2], " left out") : std::string()) << ") from " << s.source.type << " ("
      << s.source.format << ") in " << r.seconds << " s\n";
  for (const auto& c : s.cameras) {
    out << "  camera " << c.id << ": " << c.source.model << " " << c.source.width << "x" << c.source.height
        << " -> PINHOLE " << c.width << "x" << c.height << " fx " << c.fx << " fy " << c.fy << " cx " << c.cx
        << " cy " << c.cy << "\n";
  }
  out << "  box: centre (" << s.box.center.transpose() << "), size (" << s.box.size.transpose() << ")"
      << (s.box.rotation.isIdentity(1e-9) ? ", world axes" : ", aligned to the cameras' up") << "\n"
      << "       " << s.box.method << "\n";
  out << "  shells: " << s.shells.radii.size() << ", radii";
  for (double v : s.shells.radii) out << " " << v;
  out << "\n";
  for (const auto& w : r.warnings) out << "  warning: " << w << "\n";
  return out.str();
}

}  // namespace perf
