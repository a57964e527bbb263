#include "export/refined_model.h"

#include <Eigen/Geometry>
#include <map>

#include "common/errors.h"
#include "sfm_import/camera_models.h"
#include "sfm_import/colmap_model.h"

namespace perf::exporter {

namespace fs = std::filesystem;

RefinedModel WriteRefinedModel(const Scene& posed, const fs::path& workspace) {
  RefinedModel r;
  if (posed.source.type != "colmap") {
    r.not_written = "the scene was not imported from a COLMAP model (scene.json's refined_world_from_cam has the poses)";
    return r;
  }
  std::map<std::string, const SceneImage*> by_name;
  for (const SceneImage& im : posed.images) {
    if (im.refined_world_from_cam && im.split != Split::kExcluded) by_name[im.name] = &im;
  }
  if (by_name.empty()) {
    r.not_written = "no camera was refined";
    return r;
  }
  colmap::Reconstruction rec = colmap::ReadReconstruction(posed.source.path);
  uint32_t next_camera = rec.cameras.empty() ? 1 : rec.cameras.rbegin()->first + 1;
  for (auto& [id, image] : rec.images) {
    const auto it = by_name.find(image.name);
    if (it == by_name.end()) continue;
    const Eigen::Matrix<double, 3, 4>& w = *it->second->refined_world_from_cam;
    const Eigen::Matrix3d r_cw = w.leftCols<3>().transpose();
    const Eigen::Quaterniond q(r_cw);
    const Eigen::Vector3d t = -r_cw * w.col(3);
    image.qvec = {q.w(), q.x(), q.y(), q.z()};
    image.tvec = {t.x(), t.y(), t.z()};
    // Its own camera with the model's focal length(s) scaled: the refined focal is of the undistorted
    // workspace camera, which equals this to first order in the lens distortion.
    if (const std::optional<double>& f = it->second->refined_focal_scale) {
      const auto cam = rec.cameras.find(image.camera_id);
      if (cam != rec.cameras.end()) {
        colmap::Camera c = cam->second;
        c.camera_id = next_camera++;
        const int focals = colmap::NumFocalParams(static_cast<colmap::CameraModelId>(c.model_id)) == 3 ? 1 : 2;
        for (int k = 0; k < focals && k < static_cast<int>(c.params.size()); ++k) c.params[k] *= *f;
        rec.cameras[c.camera_id] = c;
        image.camera_id = c.camera_id;
      }
    }
    ++r.moved;
  }
  r.dir = "sparse_refined";
  colmap::WriteReconstruction(workspace / r.dir, rec, colmap::ModelFormat::kBinary);
  return r;
}

}  // namespace perf::exporter
