// The mesh's iso level chosen by its silhouettes (mesh_iso.h), on a hand-built faint sphere: no
// cell reaches the solid object's 0.5, so a fixed level gives an empty mesh with a warning and the
// automatic choice finds the sphere, whose silhouettes match the true ones.
#include "export/mesh_iso.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/export/synthetic_volume.h"

namespace perf::exporter {
namespace {

using test::Vec3;

Vec3 Normalised(const Vec3& v) {
  const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return {v[0] / n, v[1] / n, v[2] / n};
}
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// A 96x80 camera at `eye` looking at `target` (x right, y down, z forward).
recon::PinholeCamera<float> LookAt(const Vec3& eye, const Vec3& target) {
  const Vec3 z = Normalised({target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]});
  const Vec3 x = Normalised(Cross(z, {0, 0, 1}));
  const Vec3 y = Cross(z, x);
  recon::PinholeCamera<float> cam{};
  cam.fx = cam.fy = 90;
  cam.cx = 48;
  cam.cy = 40;
  for (int r = 0; r < 3; ++r) {
    cam.world_from_cam[4 * r + 0] = static_cast<float>(x[r]);
    cam.world_from_cam[4 * r + 1] = static_cast<float>(y[r]);
    cam.world_from_cam[4 * r + 2] = static_cast<float>(z[r]);
    cam.world_from_cam[4 * r + 3] = static_cast<float>(eye[r]);
  }
  return cam;
}

// The true silhouette of the sphere (centre, radius): pixels whose central ray passes within it.
SilhouetteMask SphereMask(const recon::PinholeCamera<float>& cam, const Vec3& centre, double radius) {
  SilhouetteMask mask{96, 80, std::vector<uint8_t>(96 * 80, 0)};
  const float* m = cam.world_from_cam;
  const Vec3 eye{m[3], m[7], m[11]};
  for (int py = 0; py < mask.height; ++py) {
    for (int px = 0; px < mask.width; ++px) {
      const double cx = (px + 0.5 - cam.cx) / cam.fx, cy = (py + 0.5 - cam.cy) / cam.fy;
      const Vec3 d = Normalised({m[0] * cx + m[1] * cy + m[2], m[4] * cx + m[5] * cy + m[6], m[8] * cx + m[9] * cy + m[10]});
      const Vec3 to{centre[0] - eye[0], centre[1] - eye[1], centre[2] - eye[2]};
      const double along = to[0] * d[0] + to[1] * d[1] + to[2] * d[2];
      const double off2 = to[0] * to[0] + to[1] * to[1] + to[2] * to[2] - along * along;
      mask.inside[static_cast<size_t>(py * mask.width + px)] = off2 < radius * radius ? 1 : 0;
    }
  }
  return mask;
}

class MeshIsoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    checkpoint_ = test::EmptyCheckpoint(32);
    centre_ = test::LocalToWorld(checkpoint_, {0.1, -0.2, 0.05});
    // At most 0.2 opaque across a voxel: a fog-like fit, as regularisation leaves a real capture.
    const auto sphere = test::SmoothSphere(centre_, kRadius, 0.03);
    test::Paint(&checkpoint_, [&](const Vec3& p) { return 0.2 * sphere(p); }, {0.8f, 0.4f, 0.2f});
    for (const Vec3& dir : {Vec3{1, 0.2, 0.3}, Vec3{-0.3, 1, 0.1}, Vec3{0.2, -0.6, 0.8}}) {
      const Vec3 u = Normalised(dir);
      const Vec3 eye{centre_[0] + 4 * u[0], centre_[1] + 4 * u[1], centre_[2] + 4 * u[2]};
      views_.cameras.push_back(LookAt(eye, centre_));
      views_.masks.push_back(SphereMask(views_.cameras.back(), centre_, kRadius));
    }
  }
  static constexpr double kRadius = 0.6;
  recon::Checkpoint checkpoint_;
  Vec3 centre_;
  Silhouettes views_;
};

TEST_F(MeshIsoTest, AFixedLevelAboveTheFogIsAnEmptyMeshWithAWarning) {
  MeshOptions o;
  o.iso_opacity = 0.5;
  Mesh mesh;
  const IsoChoice c = ChooseIsoAndMesh(checkpoint_, o, false, views_, &mesh);
  EXPECT_TRUE(mesh.triangles.empty());
  EXPECT_FALSE(c.automatic);
  EXPECT_EQ(c.iso, 0.5);
  EXPECT_EQ(c.silhouette_iou, 0.0);
  EXPECT_NE(c.warning.find("the mesh is empty"), std::string::npos) << c.warning;
  EXPECT_NE(c.warning.find("--iso auto"), std::string::npos) << c.warning;
  EXPECT_EQ(c.ToJson()["warning"], c.warning);
}

TEST_F(MeshIsoTest, TheAutomaticLevelIsTheOneWhoseSilhouettesMatchTheMasks) {
  Mesh mesh;
  const IsoChoice c = ChooseIsoAndMesh(checkpoint_, MeshOptions{}, true, views_, &mesh);
  EXPECT_TRUE(c.automatic);
  EXPECT_TRUE(c.warning.empty()) << c.warning;
  ASSERT_FALSE(mesh.triangles.empty());
  EXPECT_LT(c.iso, 0.2);  // below the fog's most
  EXPECT_GT(c.silhouette_iou, 0.93);
  ASSERT_EQ(c.tried.size(), IsoLadder().size());
  EXPECT_EQ(c.tried.front().triangles, 0) << "0.5 is above the fog";
  for (const IsoCandidate& t : c.tried) EXPECT_LE(t.iou, c.silhouette_iou + 1e-12) << t.iso;
  // The chosen surface is the sphere: its enclosed volume within 15 % of 4/3 pi r^3.
  EXPECT_NEAR(MeshVolume(mesh), 4.0 / 3 * M_PI * std::pow(kRadius, 3), 0.15 * 4.0 / 3 * M_PI * std::pow(kRadius, 3));
  EXPECT_EQ(c.ToJson()["iso_tried"].size(), IsoLadder().size()) << c.ToJson().dump();
}

TEST_F(MeshIsoTest, SilhouettesElsewhereScoreLower) {
  Mesh mesh;
  ChooseIsoAndMesh(checkpoint_, MeshOptions{}, true, views_, &mesh);
  const double right = SilhouetteIou(mesh, views_);
  Silhouettes shifted = views_;
  for (SilhouetteMask& m : shifted.masks) {  // 20 pixels to the right
    std::vector<uint8_t> moved(m.inside.size(), 0);
    for (int y = 0; y < m.height; ++y) {
      for (int x = 20; x < m.width; ++x) moved[y * m.width + x] = m.inside[y * m.width + x - 20];
    }
    m.inside = moved;
  }
  EXPECT_LT(SilhouetteIou(mesh, shifted), right - 0.2);
  EXPECT_EQ(SilhouetteIou(Mesh{}, views_), 0.0);
  EXPECT_EQ(SilhouetteIou(mesh, Silhouettes{}), -1.0);
}

}  // namespace
}  // namespace perf::exporter
