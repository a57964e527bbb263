#include "sfm_import/model_check.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "common/errors.h"
#include "sfm_import/bad_poses.h"
#include "sfm_import/bounds.h"
#include "sfm_import/camera_models.h"

namespace perf {

namespace {
constexpr double kSquarePixels = 0.01;  // how far apart a camera's fx and fy may be

// How far apart `f`'s two focal lengths are (|fx / fy - 1|; 0 where unknown).
double Apart(const ModelCheck::Focal& f) { return f.fx > 0 && f.fy > 0 ? std::abs(f.fx / f.fy - 1) : 0; }

std::string Px(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f px", v);
  return buf;
}
}  // namespace

std::string ModelCheck::Describe() const {
  return StrCat(registered, " photos, ", points, " points at ", Px(mean_error), ", ",
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
  for (const auto& [id, p] : rec.points3D) {
    if (p.error >= 0) {
      sum += p.error;
      ++n;
    }
  }
  c.mean_error = n > 0 ? sum / n : 0;
  for (const auto& [id, cam] : rec.cameras) {
    if (!colmap::FindCameraModel(cam.model_id)) continue;  // a model PERF does not know
    const colmap::FocalAndCentre f = colmap::GetFocalAndCentre(static_cast<colmap::CameraModelId>(cam.model_id),
                                                               cam.params.data());
    c.focals.push_back({cam.width, cam.height, f.fx, f.fy});
  }
  for (const BadPose& b : FindBadPoses(rec)) c.bad_poses[b.name] = b.Why();
  std::vector<BoundsCamera> cameras;
  for (const auto& [id, im] : rec.images) {
    if (c.bad_poses.count(im.name)) continue;
    if (const std::optional<BoundsCamera> cam = PinholeOf(rec, im)) cameras.push_back(*cam);
  }
  if (cameras.empty()) return c;
  if (Eigen::Vector3d p; ClosestPointToAxes(cameras, &p)) {
    c.looked_at = static_cast<double>(CamerasLookingAt(cameras, p).size()) / static_cast<double>(cameras.size());
  }
  const BoundsResult bounds = EstimateBounds(cameras, BoundsPoints(rec), BoundsOptions{}, "model check");
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
    failed.push_back(StrCat("its points fit at ", Px(repaired.mean_error), " against the model's ", Px(user.mean_error)));
  }
  // Square pixels: a new camera whose focal lengths came further apart than 1 % (or than the
  // user's) was bent to fit a wrong model. Its focal length may differ from the user's.
  double user_apart = 0;
  for (const ModelCheck::Focal& u : user.focals) user_apart = std::max(user_apart, Apart(u));
  for (const ModelCheck::Focal& f : repaired.focals) {
    if (Apart(f) <= std::max(kSquarePixels, user_apart)) continue;
    char buf[160];
    std::snprintf(buf, sizeof buf, "its camera's focal lengths differ by %.1f %% (fx %.0f, fy %.0f px)", 100 * Apart(f),
                  f.fx, f.fy);
    failed.push_back(buf);
    break;
  }
  if (user.looked_at >= 0.6 && repaired.looked_at < user.looked_at - 0.1) {
    failed.push_back(StrCat("fewer of its cameras look at a common point (", static_cast<int>(100 * repaired.looked_at),
                            " % against the model's ", static_cast<int>(100 * user.looked_at), " %)"));
  }
  std::string list;
  for (const std::string& f : failed) list += (list.empty() ? "" : "; ") + f;
  if (why != nullptr) {
    *why = failed.empty() ? StrCat("no ghost group, ", good_repaired, " photos placed well (the model: ", good_user,
                                   "), points at ", Px(repaired.mean_error), " (the model: ", Px(user.mean_error), ")")
                          : list;
  }
  return failed.empty();
}

std::string ObjectModelDoubt(const ModelCheck& check) {
  constexpr double kLookedAt = 0.8;
  std::vector<std::string> doubts;
  if (!check.ghosts.empty()) {
    doubts.push_back(StrCat("it holds ", check.ghosts.size(), check.ghosts.size() == 1 ? " ghost group (" : " ghost groups (",
                            check.ghost_photos, " photos)"));
  }
  if (check.registered >= 3 && check.looked_at < kLookedAt) {
    doubts.push_back(StrCat("only ", static_cast<int>(100 * check.looked_at), " % of its cameras look at a common point (at least ",
                            static_cast<int>(100 * kLookedAt), " % expected of an object capture)"));
  }
  // Pixels are square: a camera whose two focal lengths came apart was bent to fit a wrong model.
  for (const ModelCheck::Focal& f : check.focals) {
    if (Apart(f) <= kSquarePixels) continue;
    char buf[200];
    std::snprintf(buf, sizeof buf,
                  "its camera's focal lengths differ by %.1f %% (fx %.0f, fy %.0f px; at most %.0f %% expected of "
                  "square pixels)",
                  100 * Apart(f), f.fx, f.fy, 100 * kSquarePixels);
    doubts.push_back(buf);
    break;
  }
  std::string out;
  for (const std::string& d : doubts) out += (out.empty() ? "" : "; ") + d;
  return out;
}

std::string ObjectModelDoubtOf(const std::filesystem::path& dir) {
  try {
    return ObjectModelDoubt(CheckModel(colmap::ReadReconstruction(dir)));
  } catch (const InputError&) {
    return {};
  } catch (const IoError&) {
    return {};
  }
}

}  // namespace perf
