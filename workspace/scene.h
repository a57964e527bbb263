// The workspace's scene description, scene.json: what `perf import` writes and every later
// stage reads. Versioned and self-describing; the schema is documented in docs/scene-json.md.
//
// Conventions: camera frame x right, y down, z forward; pixel centre of the upper-left pixel at
// (0.5, 0.5); poses stored as `world_from_cam` (3x4, camera-to-world); world units and frame are
// those of the source (COLMAP's arbitrary frame, or the NeRF json's).
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace perf {

inline constexpr int kSceneVersion = 1;
// The most environment shells a scene may have (the reconstruction's kMaxShells, ray_math.h).
inline constexpr int kMaxSceneShells = 8;

// The camera as the source described it, kept so that exports can map back into the original
// (distorted) photos.
struct SourceCamera {
  std::string model;           // COLMAP model name, e.g. "OPENCV"; "PINHOLE" for NeRF json
  std::vector<double> params;  // in that model's order, at width x height
  int width = 0, height = 0;
};

struct SceneCamera {
  int id = 0;
  int width = 0, height = 0;         // workspace images (after undistortion and downscale)
  double fx = 0, fy = 0, cx = 0, cy = 0;  // pinhole, in workspace pixels
  SourceCamera source;
};

// kExcluded: left out of training and scoring (a pose that looks wrong, sfm_import/bad_poses.h);
// SceneImage::excluded_because says why.
enum class Split { kTrain, kTest, kExcluded };

// "train", "test", "excluded": scene.json's spelling.
const char* SplitName(Split split);

struct SceneImage {
  std::string name;         // as in the source (COLMAP image name or NeRF file_path)
  std::string path;         // workspace image, relative to the workspace
  std::string source_path;  // the original photo (absolute)
  std::string alpha_path;   // relative to the workspace; empty if the source had no alpha
  int camera_id = 0;
  Eigen::Matrix<double, 3, 4> world_from_cam = Eigen::Matrix<double, 3, 4>::Identity();
  // The pose as perf reconstruct --refine-poses refined it (the last level's checkpoint; a held-out
  // view's from its neighbours'), or none; world_from_cam stays the imported pose.
  std::optional<Eigen::Matrix<double, 3, 4>> refined_world_from_cam;
  // The refined focal length as a scale of its camera's fx and fy (--refine-intrinsics focal), or
  // none: the camera's.
  std::optional<double> refined_focal_scale;
  Split split = Split::kTrain;
  std::string excluded_because;  // why, when split is kExcluded (empty otherwise)
  // Why its imported pose is in doubt although it is kept (perf import: a photo of a group that
  // sees a second copy of the object, sfm_import/ghost_groups.h); empty otherwise.
  std::string pose_doubt;
  // A group of photos whose turn about the object is not known (the ghost repair moved it onto
  // the object without matches, sfm_import/ghost_move.h): perf reconstruct searches the turn
  // (recon_cuda/run/turn_search.h) and clears this. -1: none; else the group's number.
  int turn_group = -1;
};

// Axis-aligned in the box's own frame: world point p is inside when
// |R^T (p - center)| <= size / 2 componentwise, R = rotation (world_from_box).
struct SceneBox {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  Eigen::Vector3d size = Eigen::Vector3d::Ones();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  std::string method;  // how it was placed (for the summary and for users)
};

// Concentric spheres around `center`, radii strictly increasing; the outermost is opaque.
struct SceneShells {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  std::vector<double> radii;
};

struct SceneSource {
  std::string type;    // "colmap" or "nerf"
  std::string path;    // the sparse model folder or transforms.json (absolute)
  std::string images;  // the image folder (absolute)
  std::string format;  // "binary", "text" or "json"
  int downscale = 1;   // the integer factor applied on import (1: none)
  int max_size = 0;    // or the longest side the photos were fitted into on import (0: none; -1: not recorded)
};

struct Scene {
  int version = kSceneVersion;
  SceneSource source;
  std::string color_encoding = "srgb";  // pixel values as stored in the photos
  Eigen::Vector3d background = Eigen::Vector3d::Ones();  // what RGBA images were composited over
  SceneBox box;
  SceneShells shells;
  std::vector<SceneCamera> cameras;
  std::vector<SceneImage> images;

  const SceneCamera& camera(int id) const;  // throws InternalError if missing
};

// Whether every image has an alpha image (its photo was RGBA, composited over `background` on
// import); false for a scene without images.
bool EveryImageHasAlpha(const Scene& scene);
// Whether some image is left out (Split::kExcluded).
bool AnyExcluded(const Scene& scene);

// Serialises to JSON text (pretty, full precision).
std::string SceneToJson(const Scene& scene);
// Parses and validates (version, references, finite values); `name` is used in messages.
Scene SceneFromJson(const std::string& text, const std::string& name);

// A name taken from an input (a COLMAP image name, a NeRF file_path) made safe to use as a
// relative path inside the workspace: '/'-separated, no root, no "." or empty components, ".."
// replaced by "_up_" (so "../x.png" and "x.png" stay apart), backslashes and control characters
// replaced by '_'. Never empty.
std::string WorkspaceSafeName(std::string_view name);
// Whether `path` (scene.json's image paths) is relative and stays inside the workspace.
bool IsInsideWorkspace(std::string_view path);

// Path overloads: WriteScene is atomic (and durable: later stages trust it).
void WriteScene(const std::filesystem::path& path, const Scene& scene);
Scene ReadScene(const std::filesystem::path& path);

}  // namespace perf
