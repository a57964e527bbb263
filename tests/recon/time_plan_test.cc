// The time plan of perf run --time-budget (time_plan.h): which levels run and for how many
// iterations, from the levels' measured and estimated costs.
#include <gtest/gtest.h>

#include <numeric>

#include "recon_cuda/run/time_plan.h"

namespace perf::recon {
namespace {

double Seconds(const std::vector<LevelEstimate>& e, const std::vector<int>& plan) {
  double s = 0;
  for (size_t j = 0; j < e.size(); ++j) s += plan[j] > 0 ? e[j].setup + plan[j] * e[j].iteration : 0;
  return s;
}

TEST(PlanIterations, EveryCapWhereAllFit) {
  const std::vector<LevelEstimate> e{{0, 1.0, 30}, {2, 2.0, 30}};
  EXPECT_EQ(PlanIterations(100, e), (std::vector<int>{30, 30}));
}

TEST(PlanIterations, TheFinestLevelGetsItsShareWhereTheyDoNot) {
  // 60 s for levels of 1 s and 2 s an iteration (2 s setup): the first gets a third, the second the rest.
  const std::vector<LevelEstimate> e{{0, 1.0, 30}, {2, 2.0, 30}};
  const std::vector<int> plan = PlanIterations(60, e);
  EXPECT_EQ(plan[0], 20);
  EXPECT_EQ(plan[1], 19);  // (60 - 20 - 2) / 2
  EXPECT_LE(Seconds(e, plan), 60.0);
}

TEST(PlanIterations, ALevelThatCannotRunItsMinimumIsLeftOut) {
  // The finest would get (12 - 4 - 5) / 10 = 0 iterations: the run ends at the first, which gets it all.
  const std::vector<LevelEstimate> e{{0, 1.0, 30}, {5, 10.0, 30}};
  const std::vector<int> plan = PlanIterations(12, e);
  EXPECT_EQ(plan[1], 0);
  EXPECT_EQ(plan[0], 12);
  // Three levels: the last left out, the middle one becomes the finest with at least the minimum.
  const std::vector<LevelEstimate> three{{0, 0.5, 30}, {1, 1.0, 30}, {10, 20.0, 30}};
  const std::vector<int> p3 = PlanIterations(30, three);
  EXPECT_EQ(p3[2], 0);
  EXPECT_GE(p3[1], kMinFinestIterations);
  EXPECT_GT(p3[0], 0);
  EXPECT_LE(Seconds(three, p3), 30.0);
}

TEST(PlanIterations, TimeTheFinestCannotUseGoesToTheLevelsBefore) {
  // 35 s: the first level's share is 11 iterations, the finest is capped at 5 (10 s of its 24 s):
  // the first takes the 14 s left.
  const std::vector<LevelEstimate> e{{0, 1.0, 30}, {0, 2.0, 5}};
  const std::vector<int> plan = PlanIterations(35, e);
  EXPECT_EQ(plan[1], 5);
  EXPECT_EQ(plan[0], 25);
  EXPECT_LE(Seconds(e, plan), 35.0);
}

TEST(PlanIterations, TheFirstLevelRunsAtLeastOnce) {
  const std::vector<LevelEstimate> e{{0, 5.0, 30}, {2, 10.0, 30}};
  EXPECT_EQ(PlanIterations(0.5, e), (std::vector<int>{1, 0}));
  EXPECT_EQ(PlanIterations(-3, e), (std::vector<int>{1, 0}));
}

// 10 s, of which 20 have passed.
TimeBudget SpentBudget() {
  TimeBudget b;
  b.seconds = 10;
  b.start = WallClock::now() - std::chrono::seconds(20);
  return b;
}

// A budget already spent (by perf sfm, say): the first level still runs its floor of
// kMinFirstIterations, then the planner ends the run and leaves out the next level, saying why.
TEST(TimePlanner, ABudgetSpentEndsTheRunAfterTheFirstLevelsFloorAndSaysWhy) {
  TimePlanner plan(SpentBudget(), 32, {30, 30}, {1000, 1000});
  ASSERT_TRUE(plan.BeforeLevel(0));
  plan.LevelStarted(0);
  int measured = 0;
  for (int it = 1; it < kMinFirstIterations; ++it) {
    EXPECT_EQ(plan.AfterIteration(0, it, [&] { ++measured; return 1.0; }), PlanVerdict::kGoOn) << it;
  }
  EXPECT_EQ(plan.AfterIteration(0, kMinFirstIterations, [&] { ++measured; return 1.0; }), PlanVerdict::kStop);
  EXPECT_EQ(measured, 1);
  EXPECT_NE(plan.stopped().find("budget"), std::string::npos) << plan.stopped();
  EXPECT_FALSE(plan.BeforeLevel(1));
  EXPECT_NE(plan.TakeMessage().find("level 2 (64^3"), std::string::npos);
  const nlohmann::json j = plan.ToJson();
  EXPECT_EQ(j["budget_seconds"], 10.0);
  EXPECT_EQ(j["levels"][0]["iterations"], kMinFirstIterations);
}

// A first level capped below the floor ends by itself.
TEST(TimePlanner, TheFloorIsTheFirstLevelsCapWhereThatIsLess) {
  TimePlanner plan(SpentBudget(), 32, {3, 30}, {1000, 1000});
  ASSERT_TRUE(plan.BeforeLevel(0));
  plan.LevelStarted(0);
  for (int it = 1; it <= 3; ++it) EXPECT_EQ(plan.AfterIteration(0, it, [] { return 1.0; }), PlanVerdict::kGoOn) << it;
  EXPECT_FALSE(plan.BeforeLevel(1));
}

// A budget that holds everything: the plan changes nothing.
TEST(TimePlanner, ABudgetThatHoldsEveryIterationChangesNothing) {
  TimeBudget b;
  b.seconds = 3600;
  b.start = WallClock::now();
  TimePlanner plan(b, 32, {5, 5}, {1000, 4000});
  for (int level = 0; level < 2; ++level) {
    ASSERT_TRUE(plan.BeforeLevel(level));
    plan.LevelStarted(level);
    for (int it = 1; it <= 5; ++it) EXPECT_EQ(plan.AfterIteration(level, it, [] { return 1.0; }), PlanVerdict::kGoOn);
  }
  EXPECT_EQ(plan.stopped(), "");
  EXPECT_NE(plan.TakeMessage().find("level 2 (64^3): 5 iterations"), std::string::npos);
}

}  // namespace
}  // namespace perf::recon
