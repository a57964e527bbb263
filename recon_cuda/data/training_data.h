// The photos the solver fits, as posed pinhole images and as flat ray sets: every pixel of every
// training image is one ray (DESIGN.md "One ray"). Coarse levels may use a downscaled copy of the
// images (an image pyramid), which cuts their rays by 4x per halving.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "common/comm.h"
#include "recon_cuda/core/ray_math.h"
#include "recon_cuda/data/volume.h"
#include "workspace/image.h"
#include "workspace/scene.h"

namespace perf::recon {

struct PosedImage {
  std::string name;
  PinholeCamera<float> camera;
  Image image;  // RGB float, as stored (sRGB-encoded values)
  Image alpha;  // 1 channel in [0, 1]: the photo's alpha (scene.json alpha_path), or empty
};

// One rank's share of a split's images (distributed_backend.h): contiguous in scene.json order,
// of about equal pixel counts (comm.h ContiguousShare). {0, 1}: every image.
struct ImageShare {
  int rank = 0, size = 1;
};

// The indices, among the images of `split` in scene.json order, of `share`'s images.
IndexRange ShareOfSplit(const Scene& scene, Split split, ImageShare share);

// Every image of `split` in the workspace (or only `share`'s), read with OpenImageIO and
// converted to RGB, with its alpha image when scene.json has one. Throws InputError / IoError
// naming the image when one is missing, unreadable or of the wrong size.
std::vector<PosedImage> LoadImages(const Scene& scene, const std::filesystem::path& workspace, Split split,
                                   const std::function<void(int done, int total)>& progress = {},
                                   ImageShare share = {});

PinholeCamera<float> ToPinhole(const SceneCamera& camera, const Eigen::Matrix<double, 3, 4>& world_from_cam);
// The camera's world_from_cam [R | centre] in double (the inverse of ToPinhole's pose part).
Eigen::Matrix<double, 3, 4> WorldFromCam(const PinholeCamera<float>& camera);

// The cameras and image sizes of `split`'s images as LoadImages poses them, without reading an image.
std::vector<ViewFrustum> SplitViews(const Scene& scene, Split split);

// The image (and its alpha) downscaled by an integer factor (OpenImageIO filtered resize) with its intrinsics
// scaled to match: pixel edges map to pixel edges, so f and c both divide by the factor.
PosedImage Downscaled(const PosedImage& image, int factor);
// Each image Downscaled, in parallel (the resizes are single-threaded each).
std::vector<PosedImage> DownscaledAll(const std::vector<PosedImage>& images, int factor);

// Rays of one level. Ordered image by image in 8 x 8 pixel tiles, so that consecutive rays (one
// thread's block) meet the same cells: better cache use than scanlines.
struct RaySet {
  std::vector<PinholeCamera<float>> cameras;
  std::vector<RayPixel> pixels;
  std::vector<float> colours;  // [size(), 3]
  std::vector<float> alphas;   // [size()] when ImagesHaveAlpha, else empty
  // The index of ray 0 among all ranks' rays (0 in a single process; distributed_backend.h):
  // jitter and ray subsets follow the global index, so that N ranks fit the rays one would.
  int64_t first_index = 0;
  // [cameras.size()] each camera's exposure slot when the level solves the photos' exposures
  // (VolumeShape::exposures): its photo's index among all training photos. MakeRaySet numbers
  // the images it is given from 0; a rank's share adds its first image's index.
  std::vector<int32_t> exposure_slot;
  int64_t size() const { return static_cast<int64_t>(pixels.size()); }
  int64_t Bytes() const;
};

// Whether every image has an alpha image of its size (then MakeRaySet carries the alphas).
bool ImagesHaveAlpha(const std::vector<PosedImage>& images);

RaySet MakeRaySet(const std::vector<PosedImage>& images);

// No rays: what a render-only level (LevelProblem::rays == nullptr) passes see.
const RaySet& NoRays();

// How many pixels the box's shortest side spans in the median training view, measured at the box
// centre: the grid resolution at which a cell is about one pixel (0 without cameras).
double PixelsAcrossBox(std::span<const ViewFrustum> views, const VolumeGeometry& geometry);

// The image pyramid's rule: the largest power-of-two downscale (at most `max_factor`) that keeps
// a voxel of the n^3 grid at least one pixel wide in the median training view, measured at the
// box centre.
int PyramidFactor(std::span<const ViewFrustum> views, const VolumeGeometry& geometry, int n, int max_factor);

}  // namespace perf::recon
