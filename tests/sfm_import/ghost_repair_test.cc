// The ghost repair (ghost_repair.h) on a ghost made on purpose: shared/data/bonsai's model with
// eight well-placed photos (and what they see) moved by a known similarity, so that they see a
// half-size second bonsai. The check names them; the repair registers them again into the model
// without them (ghost_register.h) and uses the result: aligned to the original by the other photos,
// the eight are back within 0.5 degrees and 1 % of their distance from the object, and the user's
// model is byte-identical afterwards. About 5 minutes (COLMAP on 84 photos of 800 px, 2 cores):
// label slow. model_check_test has the quick cases.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

#include "common/atomic_file.h"
#include "sfm_import/colmap_pose.h"
#include "sfm_import/ghost_repair.h"
#include "tests/sfm_import/synthetic_ghost.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;

TEST(GhostRepair, AGroupMovedByASimilarityIsPutBack) {
  PERF_REQUIRE_DATA(bonsai, "bonsai");
  test::TempDir dir;
  const colmap::Reconstruction original = colmap::ReadReconstruction(bonsai / "sparse" / "0");
  const test::SyntheticGhost ghost = test::MakeSyntheticGhost(original);
  const std::set<std::string>& group = ghost.group;
  ASSERT_EQ(group.size(), 8u);
  const ModelCheck before = CheckModel(original);
  const fs::path model = dir / "project" / "sparse" / "0";
  fs::create_directories(model);
  colmap::WriteReconstruction(model, ghost.model, colmap::ModelFormat::kBinary);
  const auto files_before = test::FilesUnder(model);

  // The check names the moved photos as a ghost group (model_check_test too, quickly).
  const ModelCheck ghosted = CheckModel(colmap::ReadReconstruction(model));
  std::set<std::string> named;
  for (const GhostGroup& g : ghosted.ghosts) named.insert(g.names.begin(), g.names.end());
  for (const std::string& name : group) ASSERT_TRUE(named.count(name)) << name << ": " << ghosted.Describe();

  RepairOptions o;
  o.model = model;
  o.images = bonsai / "images";
  o.workspace = dir / "ws";
  o.say = [](const std::string& line) { std::printf("%s\n", line.c_str()); };
  const RepairResult r = RepairModel(o);
  EXPECT_EQ(test::FilesUnder(model), files_before) << "the user's model changed";
  ASSERT_TRUE(r.attempted);
  EXPECT_FALSE(r.why.empty());
  ASSERT_TRUE(r.used) << r.why;
  EXPECT_EQ(r.route, "register") << "registering the group again is the first route: " << r.why;
  EXPECT_EQ(r.model, dir / "ws" / "sparse_repaired");
  EXPECT_TRUE(r.after.ghosts.empty()) << r.after.Describe();
  const colmap::Reconstruction repaired = colmap::ReadReconstruction(r.model);

  // The repaired model's gauge onto the original's, by the other photos that both place well.
  std::map<std::string, const colmap::Image*> by_name;
  for (const auto& [id, im] : repaired.images) by_name[im.name] = &im;
  std::vector<Eigen::Vector3d> from, to;
  for (const auto& [id, im] : original.images) {
    const bool doubtful = group.count(im.name) || named.count(im.name) || before.bad_poses.count(im.name);
    if (doubtful || !by_name.count(im.name)) continue;
    from.push_back(test::Centre(*by_name[im.name]));
    to.push_back(test::Centre(im));
  }
  ASSERT_GE(from.size(), 20u);
  Eigen::Matrix3Xd a(3, from.size()), b(3, to.size());
  for (size_t k = 0; k < from.size(); ++k) a.col(k) = from[k], b.col(k) = to[k];
  const Eigen::Matrix4d align = Eigen::umeyama(a, b, true);
  const double scale = align.block<3, 3>(0, 0).col(0).norm();
  const Eigen::Matrix3d rot = align.block<3, 3>(0, 0) / scale;
  for (const auto& [id, im] : original.images) {
    if (!group.count(im.name)) continue;
    ASSERT_TRUE(by_name.count(im.name)) << im.name << " is not in the repaired model";
    const Eigen::Matrix<double, 3, 4> truth = WorldFromCam(im), got = WorldFromCam(*by_name[im.name]);
    const Eigen::Vector3d centre = (align * got.col(3).homogeneous()).head<3>();
    const Eigen::Matrix3d r = rot * got.leftCols<3>();
    const double degrees = Eigen::AngleAxisd(r.transpose() * truth.leftCols<3>()).angle() * 180 / M_PI;
    const double fraction = (centre - truth.col(3)).norm() / (truth.col(3) - ghost.object).norm();
    std::printf("%s: %.3f degrees, %.3f %% of its distance\n", im.name.c_str(), degrees, 100 * fraction);
    EXPECT_LT(degrees, 0.5) << im.name;
    EXPECT_LT(fraction, 0.01) << im.name;
  }
}

}  // namespace
}  // namespace perf
