#include "sfm_import/bounds.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "common/errors.h"

namespace perf {
namespace {

// A camera at `centre` looking at `target`, with `up` as the image's up direction.
BoundsCamera LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target,
                    const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ(), double f = 300) {
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = z.cross(up).normalized();  // right
  const Eigen::Vector3d y = z.cross(x);                // down
  BoundsCamera c;
  c.world_from_cam.col(0) = x;
  c.world_from_cam.col(1) = y;
  c.world_from_cam.col(2) = z;
  c.world_from_cam.col(3) = centre;
  c.fx = c.fy = f;
  c.width = 400;
  c.height = 300;
  c.cx = 200;
  c.cy = 150;
  return c;
}

// A 360-degree ring of cameras at height 1 around `centre`, radius 4.
std::vector<BoundsCamera> Ring(const Eigen::Vector3d& centre, int n = 24) {
  std::vector<BoundsCamera> cams;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    cams.push_back(LookAt(centre + Eigen::Vector3d(4 * std::cos(a), 4 * std::sin(a), 1.0), centre));
  }
  return cams;
}

TEST(Bounds, ClosestPointToAxesFindsTheTarget) {
  const Eigen::Vector3d target(0.3, -0.2, 0.5);
  Eigen::Vector3d p;
  ASSERT_TRUE(ClosestPointToAxes(Ring(target), &p));
  EXPECT_LT((p - target).norm(), 1e-9);
}

TEST(Bounds, ParallelAxesHaveNoClosestPoint) {
  std::vector<BoundsCamera> cams;
  for (int i = 0; i < 5; ++i) cams.push_back(LookAt({double(i), 0, 0}, {double(i), 5, 0}));
  Eigen::Vector3d p;
  EXPECT_FALSE(ClosestPointToAxes(cams, &p));
}

TEST(Bounds, ObjectInARoomKeepsTheObjectAndDropsTheWalls) {
  const Eigen::Vector3d centre(1, 2, 3);
  const auto cams = Ring(centre);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<BoundsPoint> points;
  // The object: a 1 x 0.6 x 0.8 block at the centre.
  for (int i = 0; i < 2000; ++i) {
    points.push_back({centre + Eigen::Vector3d(0.5 * u(rng), 0.3 * u(rng), 0.4 * u(rng)), 4, 0.5});
  }
  // The room: walls at distance 8 that each camera only sees when facing them.
  for (int i = 0; i < 2000; ++i) {
    const double a = M_PI * u(rng);
    points.push_back({centre + Eigen::Vector3d(8 * std::cos(a), 8 * std::sin(a), 2 * u(rng)), 5, 0.8});
  }
  // Outliers: badly triangulated (high error) and barely seen points far away.
  points.push_back({centre + Eigen::Vector3d(0.9, 0.0, 0.0) * 3, 5, 9.0});
  points.push_back({centre + Eigen::Vector3d(100, 100, 100), 2, 0.1});

  const BoundsResult r = EstimateBounds(cams, points, BoundsOptions{}, "model");
  EXPECT_TRUE(r.object_centric);
  EXPECT_LT((r.axes_point - centre).norm(), 1e-6);
  // The box is aligned to the ring's up (+z) and holds the block, with a little padding.
  EXPECT_GT(r.box.rotation.col(2).dot(Eigen::Vector3d::UnitZ()), 0.999);
  for (int s : {-1, 1})
    for (int t : {-1, 1})
      for (int w : {-1, 1}) {
        const Eigen::Vector3d corner = centre + Eigen::Vector3d(0.47 * s, 0.28 * t, 0.37 * w);
        const Eigen::Vector3d local = r.box.rotation.transpose() * (corner - r.box.center);
        EXPECT_TRUE((local.cwiseAbs().array() <= 0.5 * r.box.size.array()).all()) << corner.transpose();
      }
  // ...and is not blown up by the walls.
  EXPECT_LT(r.box.size.maxCoeff(), 1.5);
  // Shells: increasing, the innermost outside the box, the outermost beyond the walls.
  ASSERT_EQ(r.shells.radii.size(), 4u);
  EXPECT_GT(r.shells.radii.front(), 0.5 * r.box.size.norm());
  for (size_t i = 1; i < r.shells.radii.size(); ++i) EXPECT_GT(r.shells.radii[i], r.shells.radii[i - 1]);
  EXPECT_GT(r.shells.radii.back(), 8.0);
  EXPECT_LT(r.shells.radii.back(), 100.0);  // the far outlier does not count
  // The shells beyond the innermost sit at the walls, where the scene is (quantiles of the points
  // beyond the box), each at least 5 % beyond the one inside it.
  const auto& rr = r.shells.radii;
  EXPECT_NEAR(rr[1], 8.0, 0.3);
  EXPECT_NEAR(rr[2], 1.05 * rr[1], 0.3);
}

TEST(Bounds, CameraOnlyBoxIsInsideEveryView) {
  // NeRF-synthetic style: cameras on the upper hemisphere at radius 4 looking at the origin.
  std::vector<BoundsCamera> cams;
  for (int i = 0; i < 40; ++i) {
    const double az = 2 * M_PI * i / 40, el = 0.2 + 0.9 * (i % 5) / 5.0;
    const Eigen::Vector3d c(4 * std::cos(el) * std::cos(az), 4 * std::cos(el) * std::sin(az), 4 * std::sin(el));
    cams.push_back(LookAt(c, Eigen::Vector3d::Zero()));
  }
  BoundsOptions o;
  o.align_to_up = false;
  const BoundsResult r = EstimateBounds(cams, {}, o, "transforms.json");
  EXPECT_TRUE(r.object_centric);
  EXPECT_EQ(r.num_points_used, 0);
  EXPECT_TRUE(r.box.rotation.isIdentity());
  EXPECT_LT(r.box.center.norm(), 0.5);
  // The inscribed sphere of the narrowest view is inside the box; the box is not huge.
  const double r_in = 4 * std::sin(std::atan(150.0 / 300.0));
  EXPECT_GT(r.box.size.minCoeff(), 2 * r_in * 0.9);
  EXPECT_LT(r.box.size.maxCoeff(), 8.0);
  EXPECT_GT(r.shells.radii.back(), 4.0);  // beyond the cameras
}

TEST(Bounds, CoincidentPointsAreAnInputError) {
  std::vector<BoundsPoint> points(50, BoundsPoint{Eigen::Vector3d(1, 1, 1), 5, 0.1});
  try {
    EstimateBounds(Ring(Eigen::Vector3d::Zero()), points, BoundsOptions{}, "sparse/0");
    FAIL();
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("sparse/0/points3D"), std::string::npos) << msg;
    EXPECT_NE(msg.find("coincide"), std::string::npos) << msg;
    EXPECT_NE(msg.find("--box-center"), std::string::npos) << msg;
  }
}

TEST(Bounds, ForwardFacingWithoutPointsAsksForABox) {
  std::vector<BoundsCamera> cams;
  for (int i = 0; i < 5; ++i) cams.push_back(LookAt({0.1 * i, 0, 0}, {0.1 * i, 5, 0}));
  EXPECT_THROW(EstimateBounds(cams, {}, BoundsOptions{}, "x"), InputError);
}

TEST(Bounds, ShellsSitAtQuantilesOfThePointsBeyondTheBox) {
  SceneBox box;
  box.size = Eigen::Vector3d(2, 2, 2);  // innermost shell 1.05 sqrt(3) = 1.82
  BoundsOptions o;  // 4 shells: quantiles 30, 60, 90 % of the points beyond the innermost
  std::vector<double> d;
  for (int i = 0; i < 1000; ++i) d.push_back(i < 100 ? 1.0 : 10.0 + 20.0 * (i - 100) / 899.0);  // 10..30 beyond
  SceneShells s = PlaceShells(box, 3.0, d, o);
  ASSERT_EQ(s.radii.size(), 4u);
  EXPECT_NEAR(s.radii[0], 1.05 * std::sqrt(3.0), 1e-12);
  EXPECT_NEAR(s.radii[1], 16.0, 0.1);
  EXPECT_NEAR(s.radii[2], 22.0, 0.1);
  EXPECT_NEAR(s.radii[3], 28.0, 0.1);
  // A camera beyond them moves the outermost out to enclose it; the others stay.
  s = PlaceShells(box, 40.0, d, o);
  EXPECT_NEAR(s.radii[2], 22.0, 0.1);
  EXPECT_DOUBLE_EQ(s.radii[3], 44.0);
  // Points bunched at one distance still give increasing radii.
  s = PlaceShells(box, 3.0, std::vector<double>(200, 5.0), o);
  for (int k = 1; k < 4; ++k) EXPECT_GE(s.radii[k], 1.05 * s.radii[k - 1] - 1e-12);
  // Too few points beyond the box: the square ladder out to the farthest point (99th percentile).
  s = PlaceShells(box, 3.0, std::vector<double>(10, 12.0), o);
  EXPECT_DOUBLE_EQ(s.radii[3], 1.1 * 12.0);
  EXPECT_NEAR(s.radii[1], s.radii[0] + (s.radii[3] - s.radii[0]) / 9, 1e-9);
}

TEST(Bounds, SingleShellIsTheOuterOne) {
  SceneBox box;
  box.size = Eigen::Vector3d(2, 2, 2);
  BoundsOptions o;
  o.num_shells = 1;
  const SceneShells s = PlaceShells(box, 10.0, {}, o);
  ASSERT_EQ(s.radii.size(), 1u);
  EXPECT_DOUBLE_EQ(s.radii[0], 11.0);
}

}  // namespace
}  // namespace perf
