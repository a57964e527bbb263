#include "sfm_import/model_check.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "sfm_import/bad_poses.h"
#include "sfm_import/bounds.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_pose.h"

namespace perf {

std::string ModelCheck::Describe() const {
  char error[32];
  std::snprintf(error, sizeof error, "%.2f", mean_error);
  return StrCat(registered, " photos, ", points, " points at ", error, " px, ",
                bad_poses.empty() ? std::string("no pose looks wrong") : StrCat(bad_poses.size(), " poses look wrong"), ", ",
                ghosts.empty() ? std::string("no ghost group")
                               : StrCat(ghosts.size(), ghosts.size() == 1 ? " ghost group (" : " ghost groups (",
                                        ghost_photos, " photos)"));
}

ModelCheck CheckModel(const colmap::Reconstruction& rec) {
  ModelCheck c;
  c.registered = static_cast<int>(rec.images.size());
  c.points = static_cast<int>(rec.points3D.size());
  double sum = 0;
  int n = 0;
  std::vector<BoundsPoint> points;
  for (const auto& [id, p] : rec.points3D) {
    if (p.error >= 0) {
      sum += p.error;
      ++n;
    }
    points.push_back({Eigen::Vector3d(p.xyz[0], p.xyz[1], p.xyz[2]), static_cast<int>(p.track.size()), p.error});
  }
  c.mean_error = n > 0 ? sum / n : 0;
  for (const BadPose& b : FindBadPoses(rec)) c.bad_poses[b.name] = b.Why();
  std::vector<BoundsCamera> cameras;
  for (const auto& [id, im] : rec.images) {
    if (c.bad_poses.count(im.name)) continue;
    const colmap::Camera& cam = rec.cameras.at(im.camera_id);
    const colmap::FocalAndCentre f = colmap::GetFocalAndCentre(static_cast<colmap::CameraModelId>(cam.model_id), cam.params.data());
    cameras.push_back({WorldFromCam(im), f.fx, f.fy, f.cx, f.cy, static_cast<int>(cam.width),
                       static_cast<int>(cam.height)});
  }
  if (cameras.empty()) return c;
  const BoundsResult bounds = EstimateBounds(cameras, points, BoundsOptions{}, "model check");
  c.ghosts = FindGhostGroups(rec, bounds.box, c.bad_poses);
  for (const GhostGroup& g : c.ghosts) c.ghost_photos += static_cast<int>(g.names.size());
  return c;
}

bool RepairIsBetter(const ModelCheck& repaired, const ModelCheck& user, std::string* why) {
  const int good_user = user.registered - static_cast<int>(user.bad_poses.size());
  const int good_repaired = repaired.registered - static_cast<int>(repaired.bad_poses.size());
  const int needed = good_user - std::max(1, static_cast<int>(std::ceil(0.05 * good_user)));
  const double error_limit = std::max(1.5 * user.mean_error, user.mean_error + 0.5);
  std::vector<std::string> failed;
  if (!repaired.ghosts.empty()) failed.push_back(StrCat("it has ", repaired.ghosts.size(), " ghost groups too"));
  if (good_repaired < needed) {
    failed.push_back(StrCat("it places ", good_repaired, " photos well against the model's ", good_user));
  }
  if (user.mean_error > 0 && repaired.mean_error > error_limit) {
    failed.push_back(StrCat("its points fit at ", repaired.mean_error, " px against the model's ", user.mean_error));
  }
  std::string list;
  for (const std::string& f : failed) list += (list.empty() ? "" : "; ") + f;
  if (why != nullptr) {
    *why = failed.empty() ? StrCat("no ghost group, ", good_repaired, " photos placed well (the model: ", good_user,
                                   "), points at ", repaired.mean_error, " px (the model: ", user.mean_error, ")")
                          : list;
  }
  return failed.empty();
}

}  // namespace perf
