#include "sfm_import/bad_poses.h"

#include <cstdio>
#include <optional>

#include "common/errors.h"
#include "sfm_import/bounds.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_pose.h"

namespace perf {
namespace {

// The point the cameras look at: closest to the optical axes of the cameras that look towards
// the first estimate (bounds.h CamerasLookingAt), so that a few turned-away poses do not pull it;
// nullopt unless most cameras look at it (IsObjectCentric).
std::optional<Eigen::Vector3d> LookedAtPoint(const std::vector<BoundsCamera>& cameras) {
  Eigen::Vector3d p;
  if (!ClosestPointToAxes(cameras, &p) || !IsObjectCentric(cameras, p)) return std::nullopt;
  if (!ClosestPointToAxes(CamerasLookingAt(cameras, p), &p)) return std::nullopt;
  return p;
}

}  // namespace

std::string BadPose::Describe() const { return StrCat(name, ": ", Why()); }

std::string BadPose::Why() const {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f units", distance);
  std::string d = buf;
  std::snprintf(buf, sizeof buf, "%.1f", median_distance);
  std::string s = StrCat(d, " from the cameras' centre (median ", buf, "), ", points, " points (median ",
                         median_points, ")");
  if (away_degrees >= 0) {
    char from[64];
    std::snprintf(from, sizeof from, "%.1f units (median %.1f)", from_looked_at, median_from_looked_at);
    std::snprintf(buf, sizeof buf, "%.0f", away_degrees);
    s += StrCat(", ", from, " from the point the cameras look at, which is ", buf,
                " degrees off its axis and out of its view");
  }
  return s;
}

std::vector<BadPose> FindBadPoses(const colmap::Reconstruction& rec, const BadPoseOptions& o) {
  if (rec.images.size() < 4) return {};
  std::vector<Eigen::Vector3d> centres;
  std::vector<int> points;
  std::vector<std::optional<BoundsCamera>> pinholes;
  std::vector<BoundsCamera> known;
  for (const auto& [id, im] : rec.images) {
    centres.push_back(WorldFromCam(im).col(3));
    int seen = 0;
    for (const colmap::Point2D& p : im.points2D) {
      seen += p.point3D_id != colmap::kInvalidPoint3DId && rec.points3D.count(p.point3D_id) > 0;
    }
    points.push_back(seen);
    pinholes.push_back(PinholeOf(rec, im));
    if (pinholes.back()) known.push_back(*pinholes.back());
  }
  Eigen::Vector3d centre;
  for (int a = 0; a < 3; ++a) {
    std::vector<double> coord;
    for (const Eigen::Vector3d& c : centres) coord.push_back(c[a]);
    centre[a] = Median(coord);
  }
  std::vector<double> distances;
  for (const Eigen::Vector3d& c : centres) distances.push_back((c - centre).norm());
  const double median_distance = Median(distances);
  const int median_points = static_cast<int>(Median(std::vector<double>(points.begin(), points.end())));
  const std::optional<Eigen::Vector3d> looked_at = LookedAtPoint(known);
  double median_from_looked_at = 0;
  if (looked_at) {
    std::vector<double> from;
    for (const Eigen::Vector3d& c : centres) from.push_back((c - *looked_at).norm());
    median_from_looked_at = Median(from);
  }
  std::vector<BadPose> bad;
  size_t i = 0;
  for (const auto& [id, im] : rec.images) {
    const bool far_and_weak =
        distances[i] > o.max_distance_ratio * median_distance && points[i] < o.max_point_fraction * median_points;
    const bool far_and_away = looked_at && pinholes[i] &&
                              (centres[i] - *looked_at).norm() > o.away_distance_ratio * median_from_looked_at &&
                              !InFrustum(*pinholes[i], *looked_at);
    if (far_and_weak || far_and_away) {
      BadPose b{im.name, distances[i], median_distance, points[i], median_points};
      if (far_and_away) {
        b.away_degrees = DegreesOffAxis(*pinholes[i], *looked_at);
        b.from_looked_at = (centres[i] - *looked_at).norm();
        b.median_from_looked_at = median_from_looked_at;
      }
      bad.push_back(b);
    }
    ++i;
  }
  return bad;
}

}  // namespace perf
