#include "sfm_import/bounds.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_pose.h"

namespace perf {
namespace {

Eigen::Vector3d CameraCentre(const BoundsCamera& c) { return c.world_from_cam.col(3); }
Eigen::Vector3d CameraForward(const BoundsCamera& c) { return c.world_from_cam.col(2).normalized(); }
Eigen::Vector3d CameraUp(const BoundsCamera& c) { return -c.world_from_cam.col(1).normalized(); }

// q-th percentile (0..100) by nth_element; `v` is reordered.
double Percentile(std::vector<double>& v, double q) {
  PERF_CHECK(!v.empty());
  const double pos = std::clamp(q / 100.0, 0.0, 1.0) * static_cast<double>(v.size() - 1);
  const auto k = static_cast<size_t>(std::llround(pos));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// world_from_box rotation: z along the capture's up; x the direction of largest spread of
// `points` across it (or the world x axis projected) so the box hugs the object.
Eigen::Matrix3d UpAlignedRotation(const std::vector<BoundsCamera>& cameras,
                                  const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  for (const auto& c : cameras) up += CameraUp(c);
  up /= static_cast<double>(cameras.size());
  if (up.norm() < 0.5) return Eigen::Matrix3d::Identity();  // no common up: keep the world axes
  up.normalize();
  const Eigen::Matrix3d flat = Eigen::Matrix3d::Identity() - up * up.transpose();
  Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  if (points.size() >= 10) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : points) mean += p;
    mean /= static_cast<double>(points.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& p : points) {
      const Eigen::Vector3d d = flat * (p - mean);
      cov += d * d.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    x = eig.eigenvectors().col(2);
  }
  x = flat * x;
  if (x.norm() < 1e-6) x = flat * Eigen::Vector3d::UnitY();
  x.normalize();
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(1) = up.cross(x);
  r.col(2) = up;
  return r;
}

// Axis-aligned bounds (in the box frame) of `points` trimmed by `percentile` on each end.
void TrimmedExtent(const std::vector<Eigen::Vector3d>& box_points, double percentile,
                   Eigen::Vector3d* lo, Eigen::Vector3d* hi) {
  for (int a = 0; a < 3; ++a) {
    std::vector<double> v;
    v.reserve(box_points.size());
    for (const auto& p : box_points) v.push_back(p[a]);
    (*lo)[a] = Percentile(v, percentile);
    (*hi)[a] = Percentile(v, 100.0 - percentile);
  }
}

double VisibleFraction(const std::vector<BoundsCamera>& cameras, const Eigen::Vector3d& p) {
  int n = 0;
  for (const auto& c : cameras) n += InFrustum(c, p) ? 1 : 0;
  return static_cast<double>(n) / static_cast<double>(cameras.size());
}

}  // namespace

double Median(std::vector<double> v) { return Percentile(v, 50.0); }

std::optional<BoundsCamera> PinholeOf(const colmap::Reconstruction& rec, const colmap::Image& im) {
  const auto cam = rec.cameras.find(im.camera_id);
  if (cam == rec.cameras.end() || !colmap::FindCameraModel(cam->second.model_id)) return std::nullopt;
  const colmap::FocalAndCentre f =
      colmap::GetFocalAndCentre(static_cast<colmap::CameraModelId>(cam->second.model_id), cam->second.params.data());
  return BoundsCamera{WorldFromCam(im), f.fx, f.fy, f.cx, f.cy, static_cast<int>(cam->second.width),
                      static_cast<int>(cam->second.height)};
}

std::vector<BoundsPoint> BoundsPoints(const colmap::Reconstruction& rec) {
  std::vector<BoundsPoint> points;
  points.reserve(rec.points3D.size());
  for (const auto& [id, p] : rec.points3D) {
    points.push_back({Eigen::Vector3d(p.xyz[0], p.xyz[1], p.xyz[2]), static_cast<int>(p.track.size()), p.error});
  }
  return points;
}

bool IsRobustPoint(const BoundsPoint& p, const BoundsOptions& o) {
  return p.track_length >= o.min_track_length && (p.error < 0 || p.error <= o.max_reproj_error);
}

bool ClosestPointToAxes(const std::vector<BoundsCamera>& cameras, Eigen::Vector3d* point) {
  // Minimises sum_i |(I - d_i d_i^T)(p - o_i)|^2: (sum P_i) p = sum P_i o_i.
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& c : cameras) {
    const Eigen::Vector3d d = CameraForward(c);
    const Eigen::Matrix3d p = Eigen::Matrix3d::Identity() - d * d.transpose();
    a += p;
    b += p * CameraCentre(c);
  }
  if (cameras.size() < 2) return false;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(a / static_cast<double>(cameras.size()));
  if (eig.eigenvalues()(0) < 1e-3) return false;  // axes (nearly) parallel
  *point = a.ldlt().solve(b);
  return point->allFinite();
}

std::vector<BoundsCamera> CamerasLookingAt(const std::vector<BoundsCamera>& cameras, const Eigen::Vector3d& p) {
  std::vector<BoundsCamera> inward;
  for (const auto& c : cameras) {
    const Eigen::Vector3d to_p = p - CameraCentre(c);
    const double n = to_p.norm();
    if (n > 0 && to_p.dot(CameraForward(c)) / n > std::cos(30.0 * M_PI / 180.0)) inward.push_back(c);
  }
  return inward;
}

bool IsObjectCentric(const std::vector<BoundsCamera>& cameras, const Eigen::Vector3d& p) {
  return static_cast<double>(CamerasLookingAt(cameras, p).size()) >= 0.6 * static_cast<double>(cameras.size());
}

double DegreesOffAxis(const BoundsCamera& c, const Eigen::Vector3d& p) {
  const Eigen::Vector3d to_p = (p - CameraCentre(c)).normalized();
  return std::acos(std::clamp(to_p.dot(CameraForward(c)), -1.0, 1.0)) * 180.0 / M_PI;
}

bool InFrustum(const BoundsCamera& c, const Eigen::Vector3d& p) {
  const Eigen::Matrix3d r = c.world_from_cam.leftCols<3>();
  const Eigen::Vector3d x = r.transpose() * (p - CameraCentre(c));
  if (x.z() <= 0) return false;
  const double u = c.fx * x.x() / x.z() + c.cx, v = c.fy * x.y() / x.z() + c.cy;
  return u >= 0 && u <= c.width && v >= 0 && v <= c.height;
}

SceneShells PlaceShells(const SceneBox& box, double camera_radius, std::vector<double> point_distances,
                        const BoundsOptions& o) {
  PERF_CHECK(o.num_shells >= 1);
  SceneShells shells;
  shells.center = box.center;
  // Innermost just outside the box, so the crossing beyond the box exit is unique.
  const double inner = 0.5 * box.size.norm() * 1.05;
  std::vector<double> beyond;
  for (double d : point_distances) {
    if (d > inner) beyond.push_back(d);
  }
  if (o.num_shells >= 2 && static_cast<int>(beyond.size()) >= o.min_points_for_quantiles) {
    // Where the scene is: shell k at quantile outer_point_quantile k / (K - 1) of the points
    // beyond the innermost; the outermost also encloses the cameras.
    shells.radii.push_back(inner);
    for (int k = 1; k < o.num_shells; ++k) {
      double r = Percentile(beyond, 100.0 * o.outer_point_quantile * k / (o.num_shells - 1));
      if (k == o.num_shells - 1) r = std::max(r, camera_radius * o.outer_margin);
      shells.radii.push_back(std::max(r, shells.radii.back() * o.min_radius_step));
    }
    return shells;
  }
  double enclose = camera_radius;
  if (!point_distances.empty()) enclose = std::max(enclose, Percentile(point_distances, 99.0));
  const double outer = std::max({enclose * o.outer_margin, inner * o.min_outer_factor});
  if (o.num_shells == 1) {
    shells.radii = {outer};
    return shells;
  }
  for (int k = 0; k < o.num_shells; ++k) {
    const double t = static_cast<double>(k) / (o.num_shells - 1);
    shells.radii.push_back(inner + (outer - inner) * t * t);
  }
  return shells;
}

BoundsResult EstimateBounds(const std::vector<BoundsCamera>& cameras,
                            const std::vector<BoundsPoint>& points, const BoundsOptions& o,
                            const std::string& source) {
  PERF_CHECK(!cameras.empty());
  BoundsResult result;
  Eigen::Vector3d cam_mean = Eigen::Vector3d::Zero();
  for (const auto& c : cameras) cam_mean += CameraCentre(c);
  cam_mean /= static_cast<double>(cameras.size());
  if (ClosestPointToAxes(cameras, &result.axes_point)) {
    result.object_centric = IsObjectCentric(cameras, result.axes_point);
  }

  // Robust sparse points: seen by several images, low reprojection error.
  std::vector<Eigen::Vector3d> inliers;
  for (const auto& p : points) {
    if (IsRobustPoint(p, o)) inliers.push_back(p.xyz);
  }
  if (inliers.size() < 20 && !points.empty()) {  // tiny models: take what there is
    inliers.clear();
    for (const auto& p : points) inliers.push_back(p.xyz);
  }
  if (!inliers.empty()) {
    Eigen::Vector3d lo = inliers[0], hi = inliers[0];
    for (const auto& p : inliers) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    double cam_spread = 0;
    for (const auto& c : cameras) cam_spread = std::max(cam_spread, (CameraCentre(c) - cam_mean).norm());
    if ((hi - lo).norm() <= 1e-9 * std::max(1.0, cam_spread)) {
      throw InputError(source + "/points3D", "xyz",
                       StrCat("(", lo.x(), ", ", lo.y(), ", ", lo.z(), ")"),
                       StrCat("all ", inliers.size(), " sparse points coincide, so they give no extent"),
                       "re-run the reconstruction, or pass --box-center and --box-size");
    }
  }

  // The region of interest: inlier points inside the frustums of most cameras.
  std::vector<Eigen::Vector3d> roi;
  for (const auto& p : inliers) {
    if (VisibleFraction(cameras, p) >= o.min_visible_fraction) roi.push_back(p);
  }
  if (roi.size() < 20) roi = inliers;  // forward-facing or sparse: all robust points

  const bool from_points = roi.size() >= 4;
  if (!from_points && !result.object_centric) {
    throw InputError(source, "cameras", StrCat(cameras.size(), " cameras"),
                     "cannot place the box automatically: there are no sparse points and the "
                     "cameras do not look at a common point",
                     "pass --box-center X Y Z and --box-size SX SY SZ");
  }

  SceneBox& box = result.box;
  box.rotation = o.align_to_up ? UpAlignedRotation(cameras, roi) : Eigen::Matrix3d::Identity();
  const Eigen::Vector3d origin = result.object_centric ? result.axes_point : cam_mean;
  Eigen::Vector3d lo, hi;
  if (from_points) {
    std::vector<Eigen::Vector3d> local;
    local.reserve(roi.size());
    for (const auto& p : roi) local.push_back(box.rotation.transpose() * (p - origin));
    TrimmedExtent(local, o.percentile, &lo, &hi);
    result.num_points_used = static_cast<int>(roi.size());
    box.method = StrCat("sparse points seen by >= ", o.min_visible_fraction * 100,
                        "% of the cameras, ", o.percentile, "-", 100 - o.percentile, " percentile");
  } else {
    // Camera-only: sample the space around the axes point, keep what most cameras see.
    std::vector<double> dist;
    for (const auto& c : cameras) dist.push_back((CameraCentre(c) - origin).norm());
    const double half = Median(dist);
    constexpr int kN = 64;
    const double step = 2 * half / kN;
    lo = Eigen::Vector3d::Constant(1e300);
    hi = Eigen::Vector3d::Constant(-1e300);
    int kept = 0;
    for (int i = 0; i < kN; ++i)
      for (int j = 0; j < kN; ++j)
        for (int k = 0; k < kN; ++k) {
          const Eigen::Vector3d local(-half + (i + 0.5) * step, -half + (j + 0.5) * step,
                                      -half + (k + 0.5) * step);
          if (VisibleFraction(cameras, origin + box.rotation * local) >= o.grid_visible_fraction) {
            lo = lo.cwiseMin(local);
            hi = hi.cwiseMax(local);
            ++kept;
          }
        }
    if (kept == 0) {
      throw InputError(source, "cameras", StrCat(cameras.size(), " cameras"),
                       "no region of space is seen by most cameras",
                       "pass --box-center X Y Z and --box-size SX SY SZ");
    }
    lo.array() -= 0.5 * step;
    hi.array() += 0.5 * step;
    box.method = StrCat("region inside the view of >= ", o.grid_visible_fraction * 100,
                        "% of the cameras");
  }
  Eigen::Vector3d size = hi - lo;
  // A flat point set still needs a volume: no side thinner than a tenth of the longest.
  const double min_side = 0.1 * size.maxCoeff();
  for (int a = 0; a < 3; ++a) {
    if (size[a] < min_side) {
      const double mid = 0.5 * (lo[a] + hi[a]);
      lo[a] = mid - 0.5 * min_side;
      hi[a] = mid + 0.5 * min_side;
    }
  }
  size = (hi - lo) * (1 + 2 * o.padding);
  box.size = size;
  box.center = origin + box.rotation * (0.5 * (lo + hi));

  double camera_radius = 0;
  for (const auto& c : cameras) camera_radius = std::max(camera_radius, (CameraCentre(c) - box.center).norm());
  std::vector<double> d;
  for (const auto& p : inliers) d.push_back((p - box.center).norm());
  result.shells = PlaceShells(box, camera_radius, std::move(d), o);
  return result;
}

}  // namespace perf
