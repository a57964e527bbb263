// The model check and the repair's decision (model_check.h, ghost_repair.h), quickly: the rule
// that uses a new model only where it is better; a synthetic ghost moved onto the object
// (ghost_move.h); and the example's model, whose 200 px photos COLMAP cannot register: its group
// moved onto the object, said why, recorded, not tried again, the model untouched.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <set>

#include "common/atomic_file.h"
#include "sfm_import/colmap_pose.h"
#include "sfm_import/ghost_move.h"
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
  // bonsai: the given camera at fx 731, fy 722 (1.2 % apart); a new model with one focal length
  // at 819 px is used, one at 695, 669 (4 % apart) is not; 729 / 720.9 (1.1 %) is no worse.
  user.focals = {{800, 533, 731.4, 722.4}};
  good.focals = {{800, 533, 819.0, 819.0}};
  EXPECT_TRUE(RepairIsBetter(good, user, &why)) << why;
  ModelCheck same_camera = good;
  same_camera.focals = {{800, 533, 729.0, 720.9}};
  EXPECT_TRUE(RepairIsBetter(same_camera, user, &why)) << why;
  ModelCheck bent = good;
  bent.focals = {{800, 533, 695.2, 669.6}};
  EXPECT_FALSE(RepairIsBetter(bent, user, &why));
  EXPECT_NE(why.find("focal lengths differ by 3.8 %"), std::string::npos) << why;
  ModelCheck square_user = user;
  square_user.focals = {{800, 533, 731.0, 731.0}};
  EXPECT_FALSE(RepairIsBetter(same_camera, square_user, &why)) << "1.1 % apart against the user's square pixels";
  // The user's cameras look at a common point; the new model's mostly do not.
  user.looked_at = 0.95;
  ModelCheck scattered = good;
  scattered.looked_at = 0.7;
  EXPECT_FALSE(RepairIsBetter(scattered, user, &why));
  EXPECT_NE(why.find("common point"), std::string::npos) << why;
  good.looked_at = 0.9;
  EXPECT_TRUE(RepairIsBetter(good, user, &why)) << why;
}

// perf sfm's own models are made again where this says something (colmap_runner.h check_model).
TEST(ModelCheck, AnObjectModelIsDoubtedForAGhostCamerasLookingApartOrPixelsNotSquare) {
  ModelCheck c;
  c.registered = 84;
  c.looked_at = 1.0;
  EXPECT_EQ(ObjectModelDoubt(c), "");
  c.looked_at = 0.73;  // bonsai's fourth wrong model
  EXPECT_EQ(ObjectModelDoubt(c), "only 73 % of its cameras look at a common point (at least 80 % expected of an object capture)");
  c.looked_at = 0.95;
  c.ghosts.resize(2);
  c.ghost_photos = 16;
  EXPECT_EQ(ObjectModelDoubt(c), "it holds 2 ghost groups (16 photos)");
  c.ghosts.clear();
  c.focals = {{800, 533, 813.0, 813.4}};  // bonsai's model from every pair
  EXPECT_EQ(ObjectModelDoubt(c), "");
  c.focals.push_back({800, 533, 813.0, 797.0});  // its orbit bent by sequential matching
  EXPECT_EQ(ObjectModelDoubt(c),
            "its camera's focal lengths differ by 2.0 % (fx 813, fy 797 px; at most 1 % expected of square pixels)");
  PERF_REQUIRE_DATA(bonsai, "bonsai");
  EXPECT_EQ(ObjectModelDoubtOf(bonsai / "sparse" / "0"),
            "it holds 2 ghost groups (16 photos); its camera's focal lengths differ by 1.3 % (fx 731, fy 722 px; "
            "at most 1 % expected of square pixels)");
  EXPECT_EQ(ObjectModelDoubtOf(bonsai / "no such model"), "");
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

// The move of the last route on bonsai's eight moved photos (synthetic_ghost.h: scale 0.5 and a
// turn of 0.05 rad about their cameras' centroid): no ghost is named after it; each photo sees the
// object's centre nearly where its true camera does (within 1.5 degrees and 0.6 times the error
// before, its distance within 2 %); and its camera is back within the turn's reach of its true place
// (0.05 rad of its distance from the object, plus 2 %: the turn is not recovered).
TEST(GhostMove, ASyntheticGhostIsMovedOntoTheObject) {
  PERF_REQUIRE_DATA(bonsai, "bonsai");
  const colmap::Reconstruction original = colmap::ReadReconstruction(bonsai / "sparse" / "0");
  const test::SyntheticGhost ghost = test::MakeSyntheticGhost(original);
  const ModelCheck ghosted = CheckModel(ghost.model);
  std::vector<GhostGroup> ours;
  for (const GhostGroup& g : ghosted.ghosts) {
    if (ghost.group.count(g.names.front())) ours.push_back(g);
  }
  ASSERT_EQ(ours.size(), 1u) << ghosted.Describe();
  const colmap::Reconstruction moved = MoveGhostsOntoObject(ghost.model, ours);
  const ModelCheck after = CheckModel(moved);
  for (const GhostGroup& g : after.ghosts) EXPECT_FALSE(ghost.group.count(g.names.front())) << after.Describe();
  EXPECT_EQ(after.ghosts.size(), ghosted.ghosts.size() - 1) << after.Describe();
  // The object's centre in the camera's frame.
  const auto seen = [&](const colmap::Image& im) -> Eigen::Vector3d {
    const Eigen::Matrix<double, 3, 4> w = WorldFromCam(im);
    return w.leftCols<3>().transpose() * (ghost.object - w.col(3));
  };
  const auto degrees = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180 / M_PI;
  };
  for (const auto& [id, im] : original.images) {
    if (!ghost.group.count(im.name)) continue;
    const Eigen::Vector3d truth = seen(im), before = seen(ghost.model.images.at(id)), now = seen(moved.images.at(id));
    const double distance = truth.norm();
    const double centre_error = (test::Centre(moved.images.at(id)) - test::Centre(im)).norm();
    std::printf("%s: the object's centre %.2f degrees off and at %.3f of its distance before, %.2f and %.3f after; "
                "camera %.1f %% of its distance from its place\n",
                im.name.c_str(), degrees(before, truth), before.norm() / distance, degrees(now, truth),
                now.norm() / distance, 100 * centre_error / distance);
    EXPECT_LT(degrees(now, truth), std::min(1.5, 0.6 * degrees(before, truth))) << im.name;
    EXPECT_NEAR(now.norm() / distance, 1.0, 0.02) << im.name;
    EXPECT_LT(centre_error, (0.05 + 0.02) * distance) << im.name;
  }
}

TEST(GhostRepair, TheExamplesGroupIsMovedSayingWhyAndNotTriedAgain) {
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
  ASSERT_EQ(r.tries.size(), 3u) << r.why;  // made again, registered again, moved
  EXPECT_NE(r.tries[0].find("could not make a model"), std::string::npos) << r.tries[0];
  EXPECT_NE(r.tries[1].find("registered none"), std::string::npos) << r.tries[1];
  EXPECT_TRUE(r.used) << r.why;
  EXPECT_EQ(r.route, "move");
  EXPECT_EQ(r.model, dir / "ws" / "sparse_repaired");
  EXPECT_TRUE(r.after.ghosts.empty()) << r.after.Describe();
  EXPECT_TRUE(fs::exists(dir / "ws" / "repair" / "repair.json"));
  EXPECT_TRUE(fs::exists(dir / "ws" / "sparse_repaired" / "images.bin"));
  // The moved group's turn is left to perf reconstruct: the import marks its photos.
  const std::vector<std::vector<std::string>> unknown = r.TurnUnknown();
  ASSERT_EQ(unknown.size(), 1u);
  EXPECT_EQ(unknown[0], r.before.ghosts[0].names);
  EXPECT_TRUE(as_given.TurnUnknown().empty());
  Scene scene;
  for (const char* name : {"DSCF5608.JPG", "DSCF5610.JPG", "DSCF5614.JPG"}) {
    SceneImage im;
    im.name = name;
    scene.images.push_back(im);
  }
  MarkTurnUnknown(unknown, &scene);
  EXPECT_EQ(scene.images[0].turn_group, 0);
  EXPECT_EQ(scene.images[1].turn_group, -1);
  EXPECT_EQ(scene.images[2].turn_group, 0);
  EXPECT_NE(scene.images[0].pose_doubt.find("searches it"), std::string::npos) << scene.images[0].pose_doubt;
  // Again: the recorded decision, without COLMAP.
  lines.clear();
  const auto t0 = std::chrono::steady_clock::now();
  const RepairResult again = RepairModel(o);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
  EXPECT_TRUE(again.used);
  EXPECT_EQ(again.model, r.model);
  EXPECT_EQ(again.TurnUnknown(), unknown);  // the route is recorded too
  ASSERT_FALSE(lines.empty());
  EXPECT_NE(lines.back().find("as decided before"), std::string::npos) << lines.back();
  // A decision recorded by earlier rules (no "rules" in repair.json) is made again.
  const fs::path record = dir / "ws" / "repair" / "repair.json";
  nlohmann::json j = nlohmann::json::parse(ReadFileToString(record));
  EXPECT_EQ(j.value("rules", 0), 2);
  j.erase("rules");
  WriteFileAtomically(record, j.dump(2));
  lines.clear();
  const RepairResult redone = RepairModel(o);
  EXPECT_TRUE(redone.used) << redone.why;
  EXPECT_TRUE(std::none_of(lines.begin(), lines.end(), [](const std::string& l) { return l.find("as decided before") != std::string::npos; }));
  EXPECT_EQ(redone.tries.size(), 3u) << redone.why;
  EXPECT_EQ(nlohmann::json::parse(ReadFileToString(record)).value("rules", 0), 2);
  EXPECT_EQ(test::FilesUnder(example / "sparse" / "0"), model_before);
}

// Under a time budget too short for COLMAP (perf run's seconds left), the model is not made again
// nor the group registered again: each says so, the group is moved, and a later repair with time
// does not follow that decision.
TEST(GhostRepair, ABudgetTooShortForColmapMovesTheGroupAndIsNotFollowedLater) {
  const fs::path example = fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini";
  test::TempDir dir;
  RepairOptions o;
  o.model = example / "sparse" / "0";
  o.images = example / "images";
  o.workspace = dir / "ws";
  o.seconds_left = [] { return 5.0; };  // the example's 42 photos of 200 px: about 13 s estimated
  const auto t0 = std::chrono::steady_clock::now();
  const RepairResult r = RepairModel(o);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0) << "COLMAP ran";
  ASSERT_EQ(r.tries.size(), 3u) << r.why;
  EXPECT_NE(r.tries[0].find("making the model again would take about"), std::string::npos) << r.tries[0];
  EXPECT_NE(r.tries[0].find("(5 s left): not tried"), std::string::npos) << r.tries[0];
  EXPECT_NE(r.tries[1].find("registering the group again would take about"), std::string::npos) << r.tries[1];
  EXPECT_EQ(r.route, "move");
  EXPECT_TRUE(r.used) << r.why;
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(dir / "ws" / "repair" / "repair.json"));
  EXPECT_TRUE(j.value("skipped_for_time", false));
  // Later, with time: decided again (only the move here, to stay quick), not "as decided before".
  o.seconds_left = nullptr;
  o.routes = {"move"};
  std::vector<std::string> lines;
  o.say = [&](const std::string& line) { lines.push_back(line); };
  const RepairResult later = RepairModel(o);
  EXPECT_EQ(later.tries.size(), 1u) << later.why;
  EXPECT_TRUE(std::none_of(lines.begin(), lines.end(), [](const std::string& l) { return l.find("as decided before") != std::string::npos; }));
  EXPECT_FALSE(nlohmann::json::parse(ReadFileToString(dir / "ws" / "repair" / "repair.json")).value("skipped_for_time", true));
}

}  // namespace
}  // namespace perf
