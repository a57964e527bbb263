#include "sfm_import/bad_poses.h"

#include <cstdio>

#include "common/errors.h"
#include "sfm_import/bounds.h"
#include "sfm_import/colmap_pose.h"

namespace perf {

std::string BadPose::Describe() const {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f units", distance);
  std::string d = buf;
  std::snprintf(buf, sizeof buf, "%.1f", median_distance);
  return StrCat(name, ": ", d, " from the cameras' centre (median ", buf, "), ", points, " points (median ",
                median_points, ")");
}

std::vector<BadPose> FindBadPoses(const colmap::Reconstruction& rec, const BadPoseOptions& o) {
  if (rec.images.size() < 4) return {};
  std::vector<Eigen::Vector3d> centres;
  std::vector<int> points;
  for (const auto& [id, im] : rec.images) {
    centres.push_back(WorldFromCam(im).col(3));
    int seen = 0;
    for (const colmap::Point2D& p : im.points2D) {
      seen += p.point3D_id != colmap::kInvalidPoint3DId && rec.points3D.count(p.point3D_id) > 0;
    }
    points.push_back(seen);
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
  std::vector<BadPose> bad;
  size_t i = 0;
  for (const auto& [id, im] : rec.images) {
    if (distances[i] > o.max_distance_ratio * median_distance && points[i] < o.max_point_fraction * median_points) {
      bad.push_back({im.name, distances[i], median_distance, points[i], median_points});
    }
    ++i;
  }
  return bad;
}

}  // namespace perf
