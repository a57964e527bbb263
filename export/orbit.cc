#include "export/orbit.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/errors.h"

namespace perf::exporter {

namespace {

double Median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

Arc CapturedArc(const Scene& scene) {
  const double two_pi = 2 * std::numbers::pi;
  std::vector<double> azimuth;
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kExcluded) continue;
    const Eigen::Vector3d d = scene.box.rotation.transpose() * (im.world_from_cam.col(3) - scene.box.center);
    if (std::hypot(d.x(), d.y()) > 0) azimuth.push_back(std::atan2(d.y(), d.x()));
  }
  if (azimuth.empty()) return {0, two_pi};
  std::sort(azimuth.begin(), azimuth.end());
  // The largest gap between neighbours (the last one wraps round to the first).
  double gap = azimuth.front() + two_pi - azimuth.back(), gap_end = azimuth.front();
  for (size_t i = 1; i < azimuth.size(); ++i) {
    if (azimuth[i] - azimuth[i - 1] > gap) gap = azimuth[i] - azimuth[i - 1], gap_end = azimuth[i];
  }
  if (gap <= kMaxOrbitGap) return {0, two_pi};
  const double span = two_pi - gap, widen = std::max(0.0, kMinOrbitArc - span) / 2;
  return {gap_end - widen, span + 2 * widen};
}

void CheckOrbitOptions(const OrbitOptions& o) {
  if (o.frames < 1 || o.frames > kMaxOrbitFrames) {
    throw InputError("command line", "--orbit-frames", StrCat(o.frames), StrCat("must be 1 to ", kMaxOrbitFrames),
                     "0 on perf export skips the orbit");
  }
  if (!(std::abs(o.elevation_degrees) < 89)) {
    throw InputError("command line", "--orbit-elevation", StrCat(o.elevation_degrees), "must be between -89 and 89 degrees");
  }
}

std::vector<OrbitView> OrbitCameras(const Scene& scene, const OrbitOptions& o) {
  CheckOrbitOptions(o);
  if (scene.images.empty()) throw InputError("scene.json", "images", "[]", "the scene has no images", "re-run perf import");
  std::vector<double> distance, fov_y;
  for (const SceneImage& im : scene.images) {
    const SceneCamera& cam = scene.camera(im.camera_id);
    distance.push_back((im.world_from_cam.col(3) - scene.box.center).norm());
    fov_y.push_back(2 * std::atan(0.5 * cam.height / cam.fy));
  }
  const SceneCamera& first = scene.camera(scene.images.front().camera_id);
  const int width = o.width > 0 ? o.width : first.width;
  const int height = o.height > 0 ? o.height : first.height;
  const double radius = Median(distance);
  const double f = 0.5 * height / std::tan(0.5 * Median(fov_y));

  const Eigen::Matrix3d& box = scene.box.rotation;  // world_from_box
  const Eigen::Vector3d up = box.col(2);
  const double elevation = o.elevation_degrees * std::numbers::pi / 180;
  const Arc arc = o.follow_capture ? CapturedArc(scene) : Arc{0, 2 * std::numbers::pi};
  const bool full = arc.span >= 2 * std::numbers::pi;
  std::vector<OrbitView> views;
  for (int k = 0; k < o.frames; ++k) {
    // A full turn; or across the arc and back, so that the frames loop without a jump.
    const double s = static_cast<double>(k) / o.frames;
    const double a = full ? 2 * std::numbers::pi * s : arc.start + arc.span * (1 - std::abs(2 * s - 1));
    const Eigen::Vector3d dir_box(std::cos(elevation) * std::cos(a), std::cos(elevation) * std::sin(a), std::sin(elevation));
    const Eigen::Vector3d eye = scene.box.center + radius * (box * dir_box);
    // Camera frame x right, y down, z forward: right = forward x up, down = forward x right.
    const Eigen::Vector3d forward = (scene.box.center - eye).normalized();
    const Eigen::Vector3d right = forward.cross(up).normalized();
    const Eigen::Vector3d down = forward.cross(right);
    Eigen::Matrix<double, 3, 4> world_from_cam;
    world_from_cam << right, down, forward, eye;
    OrbitView v;
    v.width = width;
    v.height = height;
    v.camera.fx = v.camera.fy = static_cast<float>(f);
    v.camera.cx = static_cast<float>(0.5 * width);
    v.camera.cy = static_cast<float>(0.5 * height);
    for (int i = 0; i < 12; ++i) v.camera.world_from_cam[i] = static_cast<float>(world_from_cam(i / 4, i % 4));
    views.push_back(v);
  }
  return views;
}

}  // namespace perf::exporter
