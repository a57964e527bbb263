#include "export/mesh_iso.h"

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "common/errors.h"
#include "recon_cuda/data/training_data.h"

namespace perf::exporter {
namespace {

// The mesh's triangles filled into a view's image (no depth: a silhouette), a pixel inside when
// the mesh covers at least half of it (filled at kSuper times the size and averaged: OpenCV fills
// every pixel an edge touches, which would widen the silhouette by about a pixel). Triangles with
// a corner behind the camera are left out (they lie beside the camera, not in front of it).
cv::Mat1b MeshSilhouette(const Mesh& mesh, recon::PinholeCamera<float> cam, int width, int height) {
  constexpr int kSuper = 4;
  cam.fx *= kSuper, cam.fy *= kSuper, cam.cx *= kSuper, cam.cy *= kSuper;
  width *= kSuper, height *= kSuper;
  cv::Mat1b image(height, width, uchar{0});
  const float* m = cam.world_from_cam;  // [R | c], row-major
  constexpr int kShift = 4;              // fillConvexPoly's fixed point: 1/16 pixel
  const double limit = 4.0 * std::max(width, height);
  std::vector<cv::Point2f> projected(mesh.positions.size());
  std::vector<bool> in_front(mesh.positions.size());
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    const auto& p = mesh.positions[i];
    const double d[3] = {p[0] - m[3], p[1] - m[7], p[2] - m[11]};
    // Camera coordinates R^T (p - c): column a of R is (m[a], m[4 + a], m[8 + a]).
    double q[3];
    for (int a = 0; a < 3; ++a) q[a] = m[a] * d[0] + m[4 + a] * d[1] + m[8 + a] * d[2];
    in_front[i] = q[2] > 1e-6;
    if (!in_front[i]) continue;
    const double x = std::clamp(cam.fx * q[0] / q[2] + cam.cx, -limit, limit);
    const double y = std::clamp(cam.fy * q[1] / q[2] + cam.cy, -limit, limit);
    projected[i] = cv::Point2f(static_cast<float>(x), static_cast<float>(y));
  }
  cv::Point corners[3];
  for (const auto& t : mesh.triangles) {
    if (!in_front[t[0]] || !in_front[t[1]] || !in_front[t[2]]) continue;
    for (int k = 0; k < 3; ++k) {
      // Pixel centres at (x + 0.5, y + 0.5): OpenCV's integer pixel x covers [x - 0.5, x + 0.5).
      const cv::Point2f& p = projected[t[k]];
      corners[k] = cv::Point(static_cast<int>(std::lround((p.x - 0.5) * (1 << kShift))),
                             static_cast<int>(std::lround((p.y - 0.5) * (1 << kShift))));
    }
    cv::fillConvexPoly(image, corners, 3, cv::Scalar(255), cv::LINE_8, kShift);
  }
  cv::Mat1b small;
  cv::resize(image, small, cv::Size(width / kSuper, height / kSuper), 0, 0, cv::INTER_AREA);
  cv::threshold(small, small, 127, 255, cv::THRESH_BINARY);
  return small;
}

}  // namespace

Silhouettes RenderSilhouettes(recon::LoadedCheckpoint& loaded, const Scene& scene, double threshold, int max_views,
                              int max_side) {
  Silhouettes s;
  const std::vector<recon::ViewFrustum> views = recon::SplitViews(scene, Split::kTrain);
  if (views.empty() || max_views < 1) return s;
  const size_t count = std::min(views.size(), static_cast<size_t>(max_views));
  for (size_t k = 0; k < count; ++k) {
    const recon::ViewFrustum& v = views[k * views.size() / count];
    const double scale = std::min(1.0, static_cast<double>(max_side) / std::max(v.width, v.height));
    const int w = std::max(1, static_cast<int>(std::lround(v.width * scale)));
    const int h = std::max(1, static_cast<int>(std::lround(v.height * scale)));
    recon::PinholeCamera<float> cam = v.camera;
    cam.fx *= static_cast<float>(w) / v.width;
    cam.cx *= static_cast<float>(w) / v.width;
    cam.fy *= static_cast<float>(h) / v.height;
    cam.cy *= static_cast<float>(h) / v.height;
    const recon::RenderOutput r = loaded.backend->Render(recon::LoadedCheckpoint::kParams, cam, w, h, 0.f);
    SilhouetteMask mask{w, h, std::vector<uint8_t>(static_cast<size_t>(w) * h)};
    for (size_t i = 0; i < mask.inside.size(); ++i) mask.inside[i] = r.opacity[i] >= threshold ? 1 : 0;
    s.cameras.push_back(cam);
    s.masks.push_back(std::move(mask));
  }
  return s;
}

double SilhouetteIou(const Mesh& mesh, const Silhouettes& views) {
  double sum = 0;
  int counted = 0;
  for (size_t k = 0; k < views.masks.size(); ++k) {
    const SilhouetteMask& m = views.masks[k];
    cv::Mat1b mask(m.height, m.width);
    for (size_t i = 0; i < m.inside.size(); ++i) mask.data[i] = m.inside[i] ? 255 : 0;
    const cv::Mat1b drawn = MeshSilhouette(mesh, views.cameras[k], mask.cols, mask.rows);
    const int either = cv::countNonZero(mask | drawn);
    if (either == 0) continue;
    sum += static_cast<double>(cv::countNonZero(mask & drawn)) / either;
    ++counted;
  }
  return counted > 0 ? sum / counted : -1.0;
}

std::vector<double> IsoLadder() { return {0.5, 0.35, 0.25, 0.15, 0.1, 0.05, 0.02}; }

nlohmann::json IsoChoice::ToJson() const {
  nlohmann::json tried_json = nlohmann::json::array();
  for (const IsoCandidate& c : tried) {
    tried_json.push_back({{"iso_opacity", c.iso}, {"silhouette_iou", c.iou}, {"triangles", c.triangles}});
  }
  return {{"iso_opacity", iso},
          {"iso_chosen", automatic ? "the level whose silhouettes in the training views best match the masks"
                                   : "as given (--iso)"},
          {"silhouette_iou", silhouette_iou},
          {"iso_tried", tried_json},
          {"warning", warning}};
}

IsoChoice ChooseIsoAndMesh(const recon::Checkpoint& checkpoint, const MeshOptions& options, bool automatic,
                           const Silhouettes& views, Mesh* mesh) {
  IsoChoice choice;
  choice.automatic = automatic;
  MeshOptions o = options;
  // An empty mesh scores 0 against views, without drawing it.
  const auto score = [&](const Mesh& m) {
    return m.triangles.empty() ? (views.masks.empty() ? -1.0 : 0.0) : SilhouetteIou(m, views);
  };
  if (!automatic) {
    *mesh = ExtractMesh(checkpoint, o);
    choice.iso = o.iso_opacity;
    choice.silhouette_iou = score(*mesh);
  } else {
    double best = -2;
    for (double iso : IsoLadder()) {
      o.iso_opacity = iso;
      Mesh candidate = ExtractMesh(checkpoint, o);
      const double iou = score(candidate);
      choice.tried.push_back({iso, iou, static_cast<int64_t>(candidate.triangles.size())});
      // Without views to judge by, the first level that gives a surface; with them, a surface
      // rather than none where both score alike.
      const bool better = views.masks.empty()
                              ? (best < -1 && !candidate.triangles.empty())
                              : iou > best || (iou == best && mesh->triangles.empty() && !candidate.triangles.empty());
      if (better) {
        best = views.masks.empty() ? 0 : iou;
        choice.iso = iso;
        choice.silhouette_iou = iou;
        *mesh = std::move(candidate);
      }
    }
  }
  if (mesh->triangles.empty()) {
    const double lowest = automatic ? IsoLadder().back() : o.iso_opacity;
    choice.warning = StrCat("the mesh is empty: no cell's opacity across one voxel reaches ", lowest,
                            automatic ? " (the lowest level tried)" : "",
                            "; the fit holds no solid surface (too few iterations or levels, or the object is "
                            "outside the box): check renders/ and preview/, try more --levels or --iterations, ",
                            automatic ? "or use volume.vdb" : "or a lower --iso (or --iso auto)");
  }
  return choice;
}

}  // namespace perf::exporter
