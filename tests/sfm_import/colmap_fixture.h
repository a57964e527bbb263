// A small COLMAP project for the importer's tests: a ring of cameras around a point cloud, its
// binary model in sparse/ and PNG photos in images/.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <functional>
#include <random>
#include <string>

#include "sfm_import/colmap_model.h"
#include "workspace/image_io.h"
#include "sfm_import/importer.h"
#include "tests/test_util.h"

namespace perf::test {

namespace fs = std::filesystem;

inline constexpr int kW = 64, kH = 48, kNumImages = 10;

inline std::string ImageName(int i) { return "img_" + std::string(i < 10 ? "0" : "") + std::to_string(i) + ".png"; }

// A ring of cameras around the origin looking at a cloud of points in [-0.5, 0.5]^3, with
// photos of `photo_w` x `photo_h` on disk.
struct ColmapFixture {
  test::TempDir dir;
  fs::path model = dir / "sparse";
  fs::path images = dir / "images";
  colmap::Reconstruction rec;

  explicit ColmapFixture(int photo_w = kW, int photo_h = kH, int camera_model = 1) {
    fs::create_directories(model);
    fs::create_directories(images);
    colmap::Camera cam;
    cam.camera_id = 1;
    cam.model_id = camera_model;
    cam.width = kW;
    cam.height = kH;
    cam.params = camera_model == 1 ? std::vector<double>{60, 61, 32, 24}
                                   : std::vector<double>{60, 61, 32, 24, -0.1, 0.02, 0.001, -0.001};
    rec.cameras[1] = cam;
    for (int i = 0; i < kNumImages; ++i) {
      const double a = 2 * M_PI * i / kNumImages;
      const Eigen::Vector3d c(4 * std::cos(a), 4 * std::sin(a), 1.0);
      const Eigen::Vector3d z = (-c).normalized();
      const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
      Eigen::Matrix3d r_wc;
      r_wc << x, z.cross(x), z;
      const Eigen::Quaterniond q(Eigen::Matrix3d(r_wc.transpose()));
      const Eigen::Vector3d t = -r_wc.transpose() * c;
      colmap::Image im;
      im.image_id = static_cast<uint32_t>(i + 1);
      im.camera_id = 1;
      im.name = ImageName(i);
      im.qvec = {q.w(), q.x(), q.y(), q.z()};
      im.tvec = {t.x(), t.y(), t.z()};
      rec.images[im.image_id] = im;
      Image photo(photo_w, photo_h, 3);
      for (int y = 0; y < photo_h; ++y)
        for (int xx = 0; xx < photo_w; ++xx)
          for (int k = 0; k < 3; ++k) photo.at(xx, y, k) = (xx + y + 10 * k) % 17 / 16.f;
      WriteImage(images / im.name, photo, PixelFormat::kUInt8);
    }
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-0.5, 0.5);
    for (uint64_t p = 1; p <= 200; ++p) {
      colmap::Point3D pt;
      pt.point3D_id = p;
      pt.xyz = {u(rng), u(rng), u(rng)};
      pt.error = 0.5;
      for (int k = 0; k < 3; ++k) {
        colmap::Image& im = rec.images[static_cast<uint32_t>((p + k) % kNumImages + 1)];
        im.points2D.push_back({10.0, 10.0, p});
        pt.track.push_back({im.image_id, static_cast<uint32_t>(im.points2D.size() - 1)});
      }
      rec.points3D[p] = pt;
    }
    colmap::WriteReconstruction(model, rec, colmap::ModelFormat::kBinary);
  }

  ImportOptions Options() const {
    ImportOptions o;
    o.colmap_dir = model;
    o.images_dir = images;
    o.workspace = dir / "ws";
    return o;
  }
};

template <typename E>
std::string ExpectThrows(const std::function<void()>& f) {
  try {
    f();
  } catch (const E& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
    return {};
  }
  ADD_FAILURE() << "no exception";
  return {};
}

}  // namespace perf::test
