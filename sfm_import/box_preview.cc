#include "sfm_import/box_preview.h"

#include <cmath>
#include <limits>

#include "common/atomic_file.h"
#include "workspace/image_io.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

Eigen::Vector3d Corner(const SceneBox& box, int i) {
  const Eigen::Vector3d s((i & 1) ? 0.5 : -0.5, (i & 2) ? 0.5 : -0.5, (i & 4) ? 0.5 : -0.5);
  return box.center + box.rotation * s.cwiseProduct(box.size);
}

bool Project(const SceneCamera& c, const Eigen::Matrix<double, 3, 4>& world_from_cam,
             const Eigen::Vector3d& p, Eigen::Vector2d* px) {
  const Eigen::Vector3d x = world_from_cam.leftCols<3>().transpose() * (p - world_from_cam.col(3));
  if (x.z() <= 1e-9) return false;
  *px = {c.fx * x.x() / x.z() + c.cx, c.fy * x.y() / x.z() + c.cy};
  return true;
}

}  // namespace

std::vector<Eigen::Vector2d> ProjectBoxCorners(const Scene& scene, size_t index) {
  const SceneImage& im = scene.images.at(index);
  const SceneCamera& cam = scene.camera(im.camera_id);
  std::vector<Eigen::Vector2d> out;
  for (int i = 0; i < 8; ++i) {
    Eigen::Vector2d px;
    if (!Project(cam, im.world_from_cam, Corner(scene.box, i), &px)) {
      px.setConstant(std::numeric_limits<double>::quiet_NaN());
    }
    out.push_back(px);
  }
  return out;
}

void DrawBox(const Scene& scene, size_t index, Image* image) {
  const SceneImage& im = scene.images.at(index);
  const SceneCamera& cam = scene.camera(im.camera_id);
  for (int a = 0; a < 8; ++a) {
    for (int bit = 1; bit < 8; bit <<= 1) {
      const int b = a | bit;
      if (b == a) continue;  // each edge once: from the corner without the bit to the one with it
      const Eigen::Vector3d pa = Corner(scene.box, a), pb = Corner(scene.box, b);
      constexpr int kSteps = 400;
      for (int s = 0; s <= kSteps; ++s) {
        Eigen::Vector2d px;
        if (!Project(cam, im.world_from_cam, pa + (pb - pa) * (double(s) / kSteps), &px)) continue;
        const int x0 = static_cast<int>(std::floor(px.x())), y0 = static_cast<int>(std::floor(px.y()));
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int x = x0 + dx, y = y0 + dy;
            if (x < 0 || y < 0 || x >= image->width || y >= image->height) continue;
            for (int c = 0; c < image->channels && c < 3; ++c) image->at(x, y, c) = c == 0 ? 1.f : 0.f;
          }
      }
    }
  }
}

std::vector<fs::path> WriteBoxPreviews(const Scene& scene, const fs::path& workspace, int max_images) {
  std::vector<size_t> picks;
  for (size_t i = 0; i < scene.images.size(); ++i) {
    if (scene.images[i].split == Split::kTest) picks.push_back(i);
  }
  if (picks.empty()) {
    for (size_t i = 0; i < scene.images.size(); ++i) picks.push_back(i);
  }
  if (static_cast<int>(picks.size()) > max_images) picks.resize(static_cast<size_t>(max_images));
  EnsureWritableDirectory(workspace / "preview");
  std::vector<fs::path> written;
  for (size_t i : picks) {
    Image img = ReadImage(workspace / scene.images[i].path);
    DrawBox(scene, i, &img);
    const fs::path out = workspace / "preview" /
                         ("box_" + fs::path(scene.images[i].name).stem().string() + ".png");
    WriteImage(out, img, PixelFormat::kUInt8);
    written.push_back(out);
  }
  return written;
}

}  // namespace perf
