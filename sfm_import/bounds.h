// Placement of the reconstruction box and the environment shells (DESIGN.md "Representation").
//
// The region of interest is what most cameras look at. For a COLMAP model it is the robust
// sparse points (seen by several images, low reprojection error) that lie inside the view
// frustums of most cameras, trimmed by percentiles; for a NeRF json (no points) it is the part
// of space inside most frustums, sampled on a grid. In a 360-degree capture the walls of the room
// are seen by only the cameras facing them, so they drop out, while the object in the middle is
// seen by nearly all. The box is aligned with the capture's "up" (the mean of the cameras' up
// vectors) when that is well defined, since COLMAP's world frame is arbitrary.
//
// Shells: concentric around the box centre, the innermost just outside the box. With sparse
// points beyond it (a COLMAP model), the others sit where the scene is: at evenly spaced quantiles
// of those points' distances, the outermost at the 90th percentile (the farther points are
// painted on it) and around every camera. Without points, radii grow with the square of the
// index up to beyond the cameras (paper figure 3).
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "sfm_import/colmap_model.h"
#include "workspace/scene.h"

namespace perf {

struct BoundsCamera {
  Eigen::Matrix<double, 3, 4> world_from_cam;  // x right, y down, z forward
  double fx, fy, cx, cy;
  int width, height;
};

struct BoundsPoint {
  Eigen::Vector3d xyz;
  int track_length = 0;
  double error = -1;  // reprojection error in pixels; < 0 if unknown
};

struct BoundsOptions {
  int min_track_length = 3;        // points seen by fewer images are ignored...
  double max_reproj_error = 2.0;   // ...and so are points with a larger error (pixels)
  double min_visible_fraction = 0.75;  // of cameras whose frustum must contain an ROI point
  double grid_visible_fraction = 0.9;  // same, for the camera-only (no points) estimate
  double percentile = 1.0;         // trimmed from each end per axis (percent)
  double padding = 0.05;           // box grows by this fraction of its size on each side
  bool align_to_up = true;         // rotate the box to the cameras' mean up vector
  int num_shells = 4;
  double outer_margin = 1.1;       // outermost shell >= this x farthest camera (and farthest point without quantiles)
  double min_outer_factor = 4.0;   // without quantiles: outermost shell >= this x innermost
  // Shells at quantiles of the points beyond the innermost shell, when there are this many: the
  // radii follow where the scene's content lies, which generalises better held-out than the
  // square ladder (docs/tuning.md "Real photos: poses, shells, smoothness").
  int min_points_for_quantiles = 50;
  double outer_point_quantile = 0.9;  // the outermost shell's quantile
  double min_radius_step = 1.05;      // each radius at least this x the one inside it
};

struct BoundsResult {
  SceneBox box;
  SceneShells shells;
  Eigen::Vector3d axes_point = Eigen::Vector3d::Zero();  // closest to all optical axes
  bool object_centric = false;     // cameras look at a common point (360 capture)
  int num_points_used = 0;         // ROI points that defined the box (0: camera-only)
};

// A COLMAP image's camera as the bounds see it: the pinhole part of its model (distortion does
// not move the principal region much), or nullopt for a model PERF does not know.
std::optional<BoundsCamera> PinholeOf(const colmap::Reconstruction& rec, const colmap::Image& im);

// Every sparse point of `rec` with its track length and reprojection error.
std::vector<BoundsPoint> BoundsPoints(const colmap::Reconstruction& rec);

// A robust sparse point: seen by at least min_track_length images, with a reprojection error
// of at most max_reproj_error (or unknown).
bool IsRobustPoint(const BoundsPoint& point, const BoundsOptions& options);

// The median of `values` (of an even count, the upper of the two middle ones), by nth_element.
double Median(std::vector<double> values);

// The point closest (least squares) to all cameras' optical axes. Returns false when the axes
// are (nearly) parallel and no such point is defined.
bool ClosestPointToAxes(const std::vector<BoundsCamera>& cameras, Eigen::Vector3d* point);

// True if `p` projects inside the camera's image, in front of it.
bool InFrustum(const BoundsCamera& camera, const Eigen::Vector3d& p);

// The cameras whose optical axis is within 30 degrees of the direction to `p`.
std::vector<BoundsCamera> CamerasLookingAt(const std::vector<BoundsCamera>& cameras, const Eigen::Vector3d& p);

// Whether the cameras look at `p` (a 360-degree capture around it): 60 % of them do (CamerasLookingAt).
bool IsObjectCentric(const std::vector<BoundsCamera>& cameras, const Eigen::Vector3d& p);

// Degrees between the camera's optical axis and the direction to `p`.
double DegreesOffAxis(const BoundsCamera& camera, const Eigen::Vector3d& p);

// Places box and shells. `points` may be empty (NeRF json). `source` names the input in
// messages. Throws InputError when the points give no extent (all coincident).
BoundsResult EstimateBounds(const std::vector<BoundsCamera>& cameras,
                            const std::vector<BoundsPoint>& points, const BoundsOptions& options,
                            const std::string& source);

// Shells for a given box, the farthest camera's distance from its centre and the inlier points'
// distances from it (empty: none).
SceneShells PlaceShells(const SceneBox& box, double camera_radius, std::vector<double> point_distances,
                        const BoundsOptions& options);

}  // namespace perf
