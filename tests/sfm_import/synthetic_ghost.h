// A ghost made on purpose from shared/data/bonsai's model (ghost_repair_test, model_check_test):
// eight consecutive well-placed photos and what they see moved by a known similarity about their
// own cameras' centroid, scale 0.5: they keep their places but see a half-size copy of the bonsai
// at half its distance, as the capture's real ghost groups do (ghost_groups.h; at 0.45 the copy is
// within 2 radii of the bonsai and is not named).
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "sfm_import/colmap_model.h"
#include "sfm_import/colmap_pose.h"

namespace perf::test {

// world' = s R (X - c) + c about c.
struct Similarity {
  double s = 0.5;
  Eigen::Matrix3d r = Eigen::AngleAxisd(0.05, Eigen::Vector3d(0.2, 1, 0.1).normalized()).toRotationMatrix();
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  Eigen::Vector3d operator()(const Eigen::Vector3d& x) const { return s * r * (x - c) + c; }
};

inline Eigen::Vector3d Centre(const colmap::Image& im) { return WorldFromCam(im).col(3); }

// Moves `group`'s cameras by `sim`; every point they see is split into the original (for the other
// photos) and its moved copy (for the group's), so that the group sees a second object.
inline colmap::Reconstruction MoveGroup(colmap::Reconstruction rec, const std::set<std::string>& group, const Similarity& sim) {
  std::set<uint32_t> ids;
  for (auto& [id, im] : rec.images) {
    if (!group.count(im.name)) continue;
    ids.insert(id);
    const Eigen::Matrix<double, 3, 4> w = WorldFromCam(im);
    const Eigen::Matrix3d r_wc = sim.r * w.leftCols<3>();
    const Eigen::Vector3d c = sim(w.col(3));
    const Eigen::Quaterniond q(r_wc.transpose());
    im.qvec = {q.w(), q.x(), q.y(), q.z()};
    const Eigen::Vector3d t = -(r_wc.transpose() * c);
    im.tvec = {t.x(), t.y(), t.z()};
  }
  uint64_t next = rec.points3D.empty() ? 1 : rec.points3D.rbegin()->first + 1;
  std::map<uint64_t, colmap::Point3D> added;
  for (auto& [pid, p] : rec.points3D) {
    colmap::Point3D copy = p;
    copy.point3D_id = next;
    copy.track.clear();
    std::vector<colmap::TrackElement> kept;
    for (const colmap::TrackElement& t : p.track) (ids.count(t.image_id) ? copy.track : kept).push_back(t);
    if (copy.track.empty()) continue;
    const Eigen::Vector3d x = sim(Eigen::Vector3d(p.xyz[0], p.xyz[1], p.xyz[2]));
    copy.xyz = {x.x(), x.y(), x.z()};
    for (const colmap::TrackElement& t : copy.track) rec.images.at(t.image_id).points2D.at(t.point2D_idx).point3D_id = next;
    p.track = kept;
    added[next++] = copy;
  }
  for (auto it = rec.points3D.begin(); it != rec.points3D.end();) {
    it = it->second.track.empty() ? rec.points3D.erase(it) : std::next(it);
  }
  rec.points3D.insert(added.begin(), added.end());
  return rec;
}

struct SyntheticGhost {
  colmap::Reconstruction model;
  std::set<std::string> group;
  Similarity sim;
  Eigen::Vector3d object = Eigen::Vector3d::Zero();  // the mean of the well-seen points
};

// The eight photos from DSCF5700 on, moved about their centroid.
inline SyntheticGhost MakeSyntheticGhost(const colmap::Reconstruction& original) {
  SyntheticGhost g;
  std::vector<std::string> names;
  for (const auto& [id, im] : original.images) names.push_back(im.name);
  std::sort(names.begin(), names.end());
  const auto first = std::find_if(names.begin(), names.end(), [](const std::string& n) { return n >= "DSCF5700"; });
  g.group = std::set<std::string>(first, first + std::min<ptrdiff_t>(8, names.end() - first));
  int n = 0;
  for (const auto& [id, p] : original.points3D) {
    if (p.track.size() < 5) continue;
    g.object += Eigen::Vector3d(p.xyz[0], p.xyz[1], p.xyz[2]);
    ++n;
  }
  g.object /= std::max(n, 1);
  for (const auto& [id, im] : original.images) {
    if (g.group.count(im.name)) g.sim.c += Centre(im) / static_cast<double>(g.group.size());
  }
  g.model = MoveGroup(original, g.group, g.sim);
  return g;
}

}  // namespace perf::test
