#include "export/refined_model.h"

#include <Eigen/Geometry>
#include <map>

#include "common/errors.h"
#include "common/inputs.h"
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
  for (auto& [id, image] : rec.images) {
    const auto it = by_name.find(image.name);
    if (it == by_name.end()) continue;
    const Eigen::Matrix<double, 3, 4>& w = *it->second->refined_world_from_cam;
    const Eigen::Matrix3d r_cw = w.leftCols<3>().transpose();
    const Eigen::Quaterniond q(r_cw);
    const Eigen::Vector3d t = -r_cw * w.col(3);
    image.qvec = {q.w(), q.x(), q.y(), q.z()};
    image.tvec = {t.x(), t.y(), t.z()};
    ++r.moved;
  }
  r.dir = "sparse_refined";
  colmap::WriteReconstruction(workspace / r.dir, rec, colmap::ModelFormat::kBinary);
  return r;
}

bool RemoveStaleRefinedModel(const fs::path& workspace) {
  const fs::path dir = workspace / "sparse_refined";
  bool removed = false;
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) {
    const fs::path file = dir / f;
    std::error_code ec;
    if (fs::is_regular_file(file, ec) && !IsProtectedInput(file)) removed = fs::remove(file, ec) || removed;
  }
  std::error_code ec;
  if (fs::is_directory(dir, ec) && fs::is_empty(dir, ec)) fs::remove(dir, ec);
  return removed;
}

}  // namespace perf::exporter
