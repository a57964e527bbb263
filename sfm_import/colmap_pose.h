// A COLMAP image's pose as the workspace stores it: COLMAP keeps cam_from_world (a unit
// quaternion and a translation); scene.json keeps world_from_cam [R | camera centre].
#pragma once

#include <Eigen/Geometry>

#include "sfm_import/colmap_model.h"

namespace perf {

inline Eigen::Matrix<double, 3, 4> WorldFromCam(const colmap::Image& image) {
  const Eigen::Quaterniond q(image.qvec[0], image.qvec[1], image.qvec[2], image.qvec[3]);
  const Eigen::Matrix3d r_cw = q.normalized().toRotationMatrix();
  const Eigen::Vector3d t_cw(image.tvec[0], image.tvec[1], image.tvec[2]);
  Eigen::Matrix<double, 3, 4> world_from_cam;
  world_from_cam.leftCols<3>() = r_cw.transpose();
  world_from_cam.col(3) = -r_cw.transpose() * t_cw;
  return world_from_cam;
}

}  // namespace perf
