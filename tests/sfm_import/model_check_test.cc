// The model check and the repair's decision (model_check.h, ghost_repair.h), quickly: the rule
// that uses a new model only where it is better, and the example's model, whose 200 px photos
// COLMAP cannot register: kept, said why, recorded, not tried again, the model untouched.
#include <gtest/gtest.h>

#include <chrono>
#include <set>

#include "sfm_import/ghost_repair.h"
#include "tests/sfm_import/synthetic_ghost.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;

// The decision rule alone: a new model with a ghost, fewer photos, or worse points is not used.
TEST(GhostRepair, ANewModelIsUsedOnlyWhereItIsBetter) {
  ModelCheck user;
  user.registered = 84;
  user.mean_error = 0.6;
  user.bad_poses = {{"a", "far"}, {"b", "far"}};
  user.ghosts.resize(2);
  ModelCheck good;
  good.registered = 84;
  good.mean_error = 0.47;
  std::string why;
  EXPECT_TRUE(RepairIsBetter(good, user, &why)) << why;
  ModelCheck ghost = good;
  ghost.ghosts.resize(1);
  EXPECT_FALSE(RepairIsBetter(ghost, user, &why));
  EXPECT_NE(why.find("ghost"), std::string::npos) << why;
  ModelCheck fewer = good;
  fewer.registered = 70;  // the user's 82 well-placed photos less 5 % is 77
  EXPECT_FALSE(RepairIsBetter(fewer, user, &why));
  EXPECT_NE(why.find("70 photos"), std::string::npos) << why;
  ModelCheck worse = good;
  worse.mean_error = 1.2;  // above 0.6 + 0.5
  EXPECT_FALSE(RepairIsBetter(worse, user, &why));
  EXPECT_NE(why.find("px"), std::string::npos) << why;
  // bonsai: the given camera at fx 731, fy 722; a new model at 695, 669 (4 % apart) is not the same camera.
  user.focals = {{800, 533, 731.4, 722.4}};
  good.focals = {{800, 533, 729.0, 720.9}};
  EXPECT_TRUE(RepairIsBetter(good, user, &why)) << why;
  ModelCheck other_camera = good;
  other_camera.focals = {{800, 533, 695.2, 669.6}};
  EXPECT_FALSE(RepairIsBetter(other_camera, user, &why));
  EXPECT_NE(why.find("camera differs"), std::string::npos) << why;
  // The user's cameras look at a common point; the new model's mostly do not.
  user.looked_at = 0.95;
  ModelCheck scattered = good;
  scattered.looked_at = 0.7;
  EXPECT_FALSE(RepairIsBetter(scattered, user, &why));
  EXPECT_NE(why.find("common point"), std::string::npos) << why;
  good.looked_at = 0.9;
  EXPECT_TRUE(RepairIsBetter(good, user, &why)) << why;
}

// Eight photos of bonsai's good part moved with what they see (synthetic_ghost.h): the check names
// them as a ghost group, and no more poses look wrong than before.
TEST(ModelCheck, ASyntheticGhostIsNamed) {
  PERF_REQUIRE_DATA(bonsai, "bonsai");
  const colmap::Reconstruction original = colmap::ReadReconstruction(bonsai / "sparse" / "0");
  const ModelCheck before = CheckModel(original);
  const test::SyntheticGhost ghost = test::MakeSyntheticGhost(original);
  const ModelCheck after = CheckModel(ghost.model);
  std::set<std::string> named;
  for (const GhostGroup& g : after.ghosts) named.insert(g.names.begin(), g.names.end());
  for (const std::string& name : ghost.group) EXPECT_TRUE(named.count(name)) << name << ": " << after.Describe();
  EXPECT_EQ(after.bad_poses.size(), before.bad_poses.size()) << after.Describe();
  EXPECT_EQ(after.ghosts.size(), before.ghosts.size() + 1) << after.Describe();
}

TEST(GhostRepair, TheExamplesModelIsKeptSayingWhyAndNotTriedAgain) {
  const fs::path example = fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini";
  if (test::RunCommand("colmap -h").exit_code != 0) GTEST_SKIP() << "colmap not on PATH";
  test::TempDir dir;
  const auto model_before = test::FilesUnder(example / "sparse" / "0");
  RepairOptions o;
  o.model = example / "sparse" / "0";
  o.images = example / "images";
  o.workspace = dir / "ws";
  std::vector<std::string> lines;
  o.say = [&](const std::string& line) { lines.push_back(line); };
  o.repair = false;
  const RepairResult as_given = RepairModel(o);
  EXPECT_FALSE(as_given.attempted);
  EXPECT_EQ(as_given.before.ghost_photos, 5) << as_given.before.Describe();
  EXPECT_FALSE(fs::exists(dir / "ws" / "repair"));

  o.repair = true;
  const RepairResult r = RepairModel(o);
  EXPECT_TRUE(r.attempted);
  EXPECT_FALSE(r.used);
  EXPECT_EQ(r.model, o.model);
  EXPECT_NE(r.why.find("could not make a model"), std::string::npos) << r.why;
  EXPECT_TRUE(fs::exists(dir / "ws" / "repair" / "repair.json"));
  EXPECT_FALSE(fs::exists(dir / "ws" / "sparse_repaired"));
  // Again: the recorded decision, without COLMAP.
  lines.clear();
  const auto t0 = std::chrono::steady_clock::now();
  const RepairResult again = RepairModel(o);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
  EXPECT_FALSE(again.used);
  ASSERT_FALSE(lines.empty());
  EXPECT_NE(lines.back().find("as decided before"), std::string::npos) << lines.back();
  EXPECT_EQ(test::FilesUnder(example / "sparse" / "0"), model_before);
}

}  // namespace
}  // namespace perf
