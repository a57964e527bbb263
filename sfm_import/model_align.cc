#include "sfm_import/model_align.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <map>
#include <vector>

#include "sfm_import/bounds.h"
#include "sfm_import/colmap_pose.h"

namespace perf {

ModelAlignment AlignModelOnto(colmap::Reconstruction& rec, const colmap::Reconstruction& reference,
                              const std::set<std::string>& exclude) {
  ModelAlignment out;
  std::map<std::string, const colmap::Image*> theirs;
  for (const auto& [id, im] : reference.images) {
    if (!exclude.count(im.name)) theirs[im.name] = &im;
  }
  std::vector<Eigen::Vector3d> from, to;
  for (const auto& [id, im] : rec.images) {
    const auto it = theirs.find(im.name);
    if (it == theirs.end()) continue;
    from.push_back(WorldFromCam(im).col(3));
    to.push_back(WorldFromCam(*it->second).col(3));
  }
  if (from.size() < 3) return out;
  Eigen::Matrix3Xd a(3, from.size()), b(3, to.size());
  for (size_t k = 0; k < from.size(); ++k) a.col(k) = from[k], b.col(k) = to[k];
  const Eigen::Matrix4d sim = Eigen::umeyama(a, b, true);
  const double s = sim.block<3, 3>(0, 0).col(0).norm();
  if (!(s > 0) || !sim.allFinite()) return out;
  const Eigen::Matrix3d rot = sim.block<3, 3>(0, 0) / s;
  const Eigen::Vector3d shift = sim.block<3, 1>(0, 3);
  const auto move = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d { return s * rot * x + shift; };
  for (auto& [id, im] : rec.images) {
    const Eigen::Matrix<double, 3, 4> w = WorldFromCam(im);
    const Eigen::Matrix3d cam_from_world = (rot * w.leftCols<3>()).transpose();
    const Eigen::Vector3d t = -(cam_from_world * move(w.col(3)));
    const Eigen::Quaterniond q(cam_from_world);
    im.qvec = {q.w(), q.x(), q.y(), q.z()};
    im.tvec = {t.x(), t.y(), t.z()};
  }
  for (auto& [pid, p] : rec.points3D) {
    const Eigen::Vector3d x = move({p.xyz[0], p.xyz[1], p.xyz[2]});
    p.xyz = {x.x(), x.y(), x.z()};
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& c : to) mean += c / static_cast<double>(to.size());
  std::vector<double> errors, radii;
  for (size_t k = 0; k < from.size(); ++k) {
    errors.push_back((move(from[k]) - to[k]).norm());
    radii.push_back((to[k] - mean).norm());
  }
  out.photos = static_cast<int>(from.size());
  out.scale = s;
  out.median_error = Median(errors);
  out.camera_radius = Median(radii);
  return out;
}

}  // namespace perf
