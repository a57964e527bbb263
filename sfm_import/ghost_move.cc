#include "sfm_import/ghost_move.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <set>

#include "sfm_import/colmap_pose.h"

namespace perf {
namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

Eigen::Vector3d Vec(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

}  // namespace

colmap::Reconstruction MoveGhostsOntoObject(colmap::Reconstruction rec, const std::vector<GhostGroup>& ghosts) {
  std::set<std::string> in_any;
  for (const GhostGroup& g : ghosts) in_any.insert(g.names.begin(), g.names.end());
  for (const GhostGroup& g : ghosts) {
    const Eigen::Vector3d from = Vec(g.centre), to = Vec(g.main_centre);
    const std::set<std::string> names(g.names.begin(), g.names.end());
    std::set<uint32_t> ids;
    std::vector<double> group_distance, main_distance;
    for (const auto& [id, im] : rec.images) {
      const Eigen::Vector3d c = WorldFromCam(im).col(3);
      if (names.count(im.name)) {
        ids.insert(id);
        group_distance.push_back((c - from).norm());
      } else if (!in_any.count(im.name)) {
        main_distance.push_back((c - to).norm());
      }
    }
    const double g_med = Median(group_distance), m_med = Median(main_distance);
    if (g_med <= 0 || m_med <= 0) continue;
    const double s = m_med / g_med;
    const auto move = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d { return s * (x - from) + to; };
    for (uint32_t id : ids) {
      colmap::Image& im = rec.images.at(id);
      const Eigen::Matrix<double, 3, 4> w = WorldFromCam(im);
      const Eigen::Vector3d t = -(w.leftCols<3>().transpose() * move(w.col(3)));
      im.tvec = {t.x(), t.y(), t.z()};
    }
    for (auto& [pid, p] : rec.points3D) {
      const bool all = std::all_of(p.track.begin(), p.track.end(), [&](const colmap::TrackElement& t) { return ids.count(t.image_id) > 0; });
      if (all) {
        const Eigen::Vector3d x = move({p.xyz[0], p.xyz[1], p.xyz[2]});
        p.xyz = {x.x(), x.y(), x.z()};
        continue;
      }
      for (const colmap::TrackElement& t : p.track) {
        if (ids.count(t.image_id)) rec.images.at(t.image_id).points2D.at(t.point2D_idx).point3D_id = colmap::kInvalidPoint3DId;
      }
      p.track.erase(std::remove_if(p.track.begin(), p.track.end(), [&](const colmap::TrackElement& t) { return ids.count(t.image_id) > 0; }),
                    p.track.end());
    }
  }
  return rec;
}

}  // namespace perf
