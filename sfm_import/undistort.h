// Undistortion of COLMAP cameras to pinhole cameras with OpenCV (initUndistortRectifyMap /
// remap; cv::fisheye for the fisheye models), keeping only valid pixels: the new pinhole is
// chosen so that every output pixel maps inside the input image (OpenCV's alpha = 0 /
// balance = 0), at the input's resolution.
#pragma once

#include <memory>
#include <vector>

#include "sfm_import/colmap_model.h"
#include "workspace/image.h"

namespace perf {

// A pinhole camera in PERF's conventions (camera_models.h: pixel centre at (0.5, 0.5)).
struct PinholeIntrinsics {
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
};

// Built once per camera, then applied to each of its images. Move-only (holds OpenCV maps).
class Undistorter {
 public:
  // Throws InputError for unsupported models (naming the model and suggesting
  // `colmap image_undistorter`) and for parameter counts that do not fit the model.
  // `source` names the camera in messages (e.g. "sparse/0/cameras.bin camera 1").
  static Undistorter Create(const colmap::Camera& camera, const std::string& source);

  Undistorter(Undistorter&&) noexcept;
  Undistorter& operator=(Undistorter&&) noexcept;
  ~Undistorter();

  // The output pinhole camera (same width/height as the input camera).
  const PinholeIntrinsics& pinhole() const { return pinhole_; }
  // True for pinhole inputs: Apply copies the image unchanged.
  bool is_identity() const { return identity_; }

  // Resamples `in` (camera.width x camera.height, any channel count) to the pinhole camera with
  // bilinear interpolation.
  Image Apply(const Image& in) const;

  // Where the centre of output pixel (x, y) (PERF convention) lands in the distorted input,
  // in PERF pixel coordinates. For tests and for mapping masks back.
  void MapToDistorted(double x, double y, double* xd, double* yd) const;

  // The inverse, for every pixel centre of the distorted input (width x height, row-major):
  // where it lands in the output pinhole, PERF pixel coordinates (possibly outside the output,
  // which keeps only valid pixels). NaN where the model has no inverse (beyond a fold). Used
  // to map results (masks) back into the original photos.
  void MapFromDistorted(std::vector<float>* x, std::vector<float>* y) const;

 private:
  Undistorter() = default;
  struct Maps;
  PinholeIntrinsics pinhole_;
  bool identity_ = false;
  std::unique_ptr<Maps> maps_;
};

}  // namespace perf
