// The hierarchy's level count (level_choice.h) and its memory stop (HierarchyOptions::
// stop_when_out_of_memory) on a small synthetic scene.
#include "recon_cuda/solve/hierarchy.h"

#include <gtest/gtest.h>

#include "common/errors.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/run/level_choice.h"
#include "recon_cuda/run/reconstruct.h"
#include "tests/recon/synthetic_scene.h"
#include "workspace/scene.h"

namespace perf::recon {
namespace {

TEST(LevelChoiceTest, AutomaticLevelsReachThePhotosWithinTheCap) {
  // 215 cells across: 32, 64, 128, 256 -> 4 levels reach it; a cap of 128 keeps 3.
  LevelChoice c = ChooseLevels(0, 215, 32, 1024);
  EXPECT_TRUE(c.automatic);
  EXPECT_EQ(c.levels, 4);
  EXPECT_EQ(c.Finest(), 256);
  c = ChooseLevels(0, 215, 32, 128);
  EXPECT_EQ(c.levels, 3);
  EXPECT_NE(c.Describe().find("--max-resolution 128 stops short of 256^3"), std::string::npos) << c.Describe();
  EXPECT_EQ(ChooseLevels(0, 215, 32, 200).levels, 3);  // a cap between two levels keeps the coarser
  EXPECT_EQ(ChooseLevels(0, 256, 32, 1024).levels, 4);  // exactly reached
  EXPECT_EQ(ChooseLevels(0, 257, 32, 1024).levels, 5);
  EXPECT_EQ(ChooseLevels(0, 20, 32, 1024).levels, 1);   // coarser photos than the first level
  EXPECT_EQ(ChooseLevels(0, 0, 32, 1024).levels, 1);    // no training views
  EXPECT_EQ(ChooseLevels(0, 1e6, 32, 4096).levels, 6);  // at most 6
  EXPECT_EQ(ChooseLevels(0, 215, 16, 1024).levels, 5);
  EXPECT_EQ(ChooseLevels(0, 215, 32, 32).levels, 1);
}

// ReconstructOptions::Hierarchy: the choices perf reconstruct derives from its options and the scene.
TEST(ReconstructOptionsTest, TheHierarchyIsDerivedForTheScene) {
  Scene scene;
  scene.cameras.push_back(SceneCamera{});
  scene.source.type = "colmap";
  for (const Split split : {Split::kTrain, Split::kTrain, Split::kTrain, Split::kTest, Split::kExcluded}) {
    SceneImage im;
    im.split = split;
    scene.images.push_back(im);
  }
  scene.background = Eigen::Vector3d(0.25, 0.5, 0.75);
  ReconstructOptions o;
  o.start_resolution = 16;
  o.iterations = 7;
  o.level_iterations = {3};
  o.dense = true;
  o.sh_degree = 1;
  LevelChoice automatic = ChooseLevels(0, 100, 16, 64);
  HierarchyOptions h = o.Hierarchy(scene, automatic);
  EXPECT_EQ(h.levels, automatic.levels);
  EXPECT_TRUE(h.stop_when_out_of_memory) << "automatic levels end early for memory";
  EXPECT_EQ(h.start_resolution, 16);
  EXPECT_EQ(h.IterationsAt(0), 3);
  EXPECT_EQ(h.IterationsAt(1), 7);
  EXPECT_FALSE(h.sparse);
  EXPECT_EQ(h.sh_degree, 1);
  EXPECT_EQ(h.sh_from_level, h.levels - 1) << "by default the last level alone";
  ReconstructOptions from_first = o;
  from_first.sh_from_level = 1;
  EXPECT_EQ(from_first.Hierarchy(scene, automatic).sh_from_level, 0);
  ReconstructOptions last_two = o;
  last_two.sh_from_level = -1;
  EXPECT_EQ(last_two.Hierarchy(scene, automatic).sh_from_level, h.levels - 2) << "-1: the last two levels";
  // COLMAP photos without alpha: learned shells, the automatic grid smoothness, exposures solved.
  EXPECT_FALSE(h.fixed_background);
  EXPECT_EQ(h.solver.smooth_grid, kAutoSmoothGrid);
  EXPECT_EQ(h.solver.smooth_shells, o.solver.smooth_shells);
  EXPECT_EQ(h.exposures, 3) << "one per training photo";
  EXPECT_EQ(h.poses, 3) << "COLMAP photos: refined";
  EXPECT_EQ(h.background[2], 0.75f);
  // The pose prior: its default, the focal lengths' default, or the given weight.
  EXPECT_EQ(h.solver.pose_prior, kDefaultPosePrior);
  ReconstructOptions focal = o;
  focal.refine_focal = true;
  EXPECT_EQ(focal.Hierarchy(scene, automatic).solver.pose_prior, kFocalPosePrior);
  focal.pose_prior = 0.5;
  EXPECT_EQ(focal.Hierarchy(scene, automatic).solver.pose_prior, 0.5) << "a given weight is kept";
  focal.workspace = "ws";
  EXPECT_NO_THROW(focal.Check());
  focal.pose_prior = -0.5;
  try {
    focal.Check();
    ADD_FAILURE() << "a negative --pose-prior was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--pose-prior"), std::string::npos) << e.what();
  }

  // Every photo with alpha: fixed shells, no grid smoothness unless asked for; given levels run all.
  for (SceneImage& im : scene.images) im.alpha_path = "alpha/" + im.name;
  o.exposure = ExposureChoice::kOff;
  h = o.Hierarchy(scene, ChooseLevels(2, 100, 16, 64));
  EXPECT_TRUE(h.fixed_background);
  EXPECT_EQ(h.solver.smooth_grid, 0.0);
  EXPECT_FALSE(h.stop_when_out_of_memory);
  EXPECT_EQ(h.exposures, 0);
  o.solver.smooth_grid = 0.05;
  EXPECT_EQ(o.Hierarchy(scene, automatic).solver.smooth_grid, 0.05) << "a given weight is kept";
  o.background = BackgroundChoice::kLearn;
  EXPECT_FALSE(o.Hierarchy(scene, automatic).fixed_background);

  // Adam runs no smoothness.
  o.solver.type = SolverType::kAdam;
  h = o.Hierarchy(scene, automatic);
  EXPECT_EQ(h.solver.smooth_grid, 0.0);
  EXPECT_EQ(h.solver.smooth_shells, 0.0);
}

TEST(LevelChoiceTest, GivenLevelsAreKeptAndAdvised) {
  LevelChoice c = ChooseLevels(2, 50, 32, 128);
  EXPECT_FALSE(c.automatic);
  EXPECT_EQ(c.levels, 2);
  EXPECT_EQ(c.Describe(),
            "levels: 2 (32^3 to 64^3) as given, which resolve about 50 cells across the box (one pixel a cell in the "
            "median view)");
  EXPECT_NE(ChooseLevels(1, 215, 32, 128).Describe().find("; --levels 4 would reach 256^3"), std::string::npos);
  EXPECT_NE(ChooseLevels(3, 20, 32, 128).Describe().find("finer than the photos: --levels 1 would do"),
            std::string::npos);
  EXPECT_NE(ChooseLevels(2, 0, 32, 128).Describe().find("no training views"), std::string::npos);
}

class HierarchyMemoryTest : public ::testing::Test {
 protected:
  HierarchyMemoryTest() {
    o.levels = 3;
    o.start_resolution = 8;
    o.iterations = 1;
    o.sparse = false;  // dense levels: each needs 8x the one before
    o.min_rays_per_texel = 0;  // the shells of the ladder (ShellsFollowTheRaysOfEachLevel sets it)
  }
  // What the dense level `level` needs on a CPU backend, by its own estimate.
  int64_t Needs(int level) const {
    const RaySet rays = views.rays(1);
    const MemoryEstimate e = MakeCpuBackend({})->EstimateMemory(
        {LevelShape(o, scene.geometry.num_shells(), level), scene.geometry, &rays, o.residuals},
        RequiredVectors(o.solver.type));
    return e.vectors + e.scratch + e.rays;
  }
  const test::SyntheticScene scene{8, 8, 6, 16, 6};
  const TrainingViews views = ViewsForHierarchy(scene.train);
  HierarchyOptions o;
};

TEST_F(HierarchyMemoryTest, ALevelThatDoesNotFitEndsAutomaticLevelsAtTheOneBefore) {
  CpuBackendOptions bo;
  bo.max_memory = Needs(1) + 1000;  // 16^3 fits, 32^3 does not
  ASSERT_GT(Needs(2), bo.max_memory);
  auto backend = MakeCpuBackend(bo);
  o.stop_when_out_of_memory = true;
  std::vector<int> done, refused;
  HierarchyCallbacks cb;
  cb.level_done = [&](const HierarchyLevel& h, const SolverSummary&, const std::vector<float>&) {
    done.push_back(h.level);
  };
  cb.out_of_memory = [&](const HierarchyLevel& h) {
    refused.push_back(h.level);
    EXPECT_FALSE(h.memory.Fits());
    EXPECT_EQ(h.memory.available, bo.max_memory);
  };
  const std::vector<float> x = SolveHierarchy(backend.get(), scene.geometry, views, o, {}, cb);
  EXPECT_EQ(done, (std::vector<int>{0, 1}));
  EXPECT_EQ(refused, (std::vector<int>{2}));
  EXPECT_EQ(static_cast<int64_t>(x.size()), LevelShape(o, scene.geometry.num_shells(), 1).ParamCount());

  // Levels as given: the level that does not fit is an error.
  o.stop_when_out_of_memory = false;
  EXPECT_THROW(SolveHierarchy(backend.get(), scene.geometry, views, o, {}, {}), ResourceError);
}

// --sh-from-level: 1..6 from the first level, 0..-5 back from the last; past the last level an
// error with set levels, the last with levels from the photos.
TEST(HierarchyOptionsTest, ShFromLevelCountsFromEitherEnd) {
  const LevelChoice set{.levels = 3, .automatic = false};
  const LevelChoice automatic{.levels = 3, .automatic = true};
  EXPECT_EQ(ShFromLevelIndex(1, set), 0);
  EXPECT_EQ(ShFromLevelIndex(3, set), 2);
  EXPECT_EQ(ShFromLevelIndex(0, set), 2);
  EXPECT_EQ(ShFromLevelIndex(-1, set), 1);
  EXPECT_EQ(ShFromLevelIndex(-2, set), 0);
  EXPECT_EQ(ShFromLevelIndex(-5, set), 0) << "more levels back than there are: all of them";
  EXPECT_EQ(ShFromLevelIndex(6, automatic), 2) << "levels from the photos: at most the last";
  try {
    ShFromLevelIndex(4, set);
    ADD_FAILURE() << "level 4 of 3 accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--sh-from-level"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("past the last of the 3 levels"), std::string::npos) << e.what();
  }
  for (int bad : {-6, 7}) EXPECT_THROW(CheckShFromLevel(bad), InputError) << bad;
  for (int good : {-5, 0, 6}) EXPECT_NO_THROW(CheckShFromLevel(good)) << good;
}

// View dependence from a later level (HierarchyOptions::sh_from_level): the levels before carry
// no bands, the first level with them starts them at 0 (Resample) and solves them, and a resume
// after the band-less level gets them too (NextLevelShape of the next level).
TEST_F(HierarchyMemoryTest, SphericalHarmonicsStartAtTheirLevel) {
  o.levels = 2;
  o.iterations = 2;
  o.sh_degree = 1;
  o.sh_from_level = 1;
  EXPECT_EQ(LevelShape(o, scene.geometry.num_shells(), 0).sh_degree, 0);
  EXPECT_EQ(LevelShape(o, scene.geometry.num_shells(), 1).sh_degree, 1);
  auto backend = MakeCpuBackend({});
  std::vector<int> degrees;
  std::vector<float> first;  // level 0's fit
  VolumeShape first_shape;
  HierarchyCallbacks cb;
  cb.level_started = [&](const HierarchyLevel& h) { degrees.push_back(h.shape.sh_degree); };
  cb.level_done = [&](const HierarchyLevel& h, const SolverSummary&, const std::vector<float>& x) {
    if (h.level != 0) return;
    first = x;
    first_shape = h.shape;
  };
  const std::vector<float> x = SolveHierarchy(backend.get(), scene.geometry, views, o, {}, cb);
  EXPECT_EQ(degrees, (std::vector<int>{0, 1}));
  const VolumeShape last = LevelShape(o, scene.geometry.num_shells(), 1);
  ASSERT_EQ(static_cast<int64_t>(x.size()), last.ParamCount());
  int moved = 0;  // bands the last level solved away from their start at 0
  for (int64_t i = last.ShStart(); i < last.ExposureStart(); ++i) moved += x[i] != 0.f;
  EXPECT_GT(moved, 100);
  const VolumeShape resumed = NextLevelShape(o, scene.geometry, first_shape, first, views.views, 1);
  EXPECT_EQ(resumed.sh_degree, 1);
  EXPECT_EQ(NextLevelShape(o, scene.geometry, first_shape, first, views.views, 0).sh_degree, 0);
}

// Shell texels per face side: the ladder's, unless the rays are too few for them.
TEST(ShellResolutionTest, TheShellsStayCoarseEnoughForTheirRays) {
  // The bonsai example's 64^3 level: 369920 rays, 4 shells, 8 rays a texel: 43 texels a side.
  EXPECT_EQ(ShellResolution(64, 369920, 4, 8), 43);
  EXPECT_LE(8.0 * 6 * 43 * 43 * 4, 369920.0);
  EXPECT_GT(8.0 * 6 * 44 * 44 * 4, 369920.0);
  EXPECT_EQ(ShellResolution(32, 369920, 4, 8), 32);           // its 32^3 level: the ladder's
  EXPECT_EQ(ShellResolution(128, 7369200, 4, 8), 128);        // the full capture's 128^3 level
  EXPECT_EQ(ShellResolution(64, 369920, 4, 0), 64);           // off
  EXPECT_EQ(ShellResolution(64, 100, 4, 8), 8);               // never below 8...
  EXPECT_EQ(ShellResolution(4, 100, 4, 8), 4);                // ...nor above the ladder
}

// The hierarchy applies it level by level: a level's shells are the ladder's or coarser, never
// finer than its rays allow (above the floor of 8), and the fit carries over between levels.
TEST_F(HierarchyMemoryTest, ShellsFollowTheRaysOfEachLevel) {
  o.min_rays_per_texel = 2;
  auto backend = MakeCpuBackend({});
  std::vector<int> m, ladder;
  HierarchyCallbacks cb;
  cb.level_started = [&](const HierarchyLevel& h) {
    m.push_back(h.shape.m);
    ladder.push_back(LevelShape(o, scene.geometry.num_shells(), h.level).m);
    if (o.min_rays_per_texel > 0) {
      EXPECT_TRUE(h.shape.m <= 8 || 2.0 * 6 * h.shape.m * h.shape.m * h.shape.num_shells <= h.rays)
          << h.level << ": m " << h.shape.m << ", rays " << h.rays;
    }
    EXPECT_EQ(backend->level().shape.m, h.shape.m);
  };
  const std::vector<float> x = SolveHierarchy(backend.get(), scene.geometry, views, o, {}, cb);
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(m[0], ladder[0]);
  EXPECT_LT(m[2], ladder[2]) << "the finest level's rays are too few for its ladder's texels";
  for (size_t k = 0; k < m.size(); ++k) EXPECT_LE(m[k], ladder[k]);
  EXPECT_EQ(static_cast<int64_t>(x.size()), LevelShape(o, scene.geometry.num_shells(), 2).WithShellResolution(m[2]).ParamCount());
  o.min_rays_per_texel = 0;  // off: the ladder
  m.clear();
  ladder.clear();
  SolveHierarchy(backend.get(), scene.geometry, views, o, {}, cb);
  EXPECT_EQ(m, ladder);
}

// The robust loss starts at robust_from_level; the levels before fit by least squares.
TEST_F(HierarchyMemoryTest, TheRobustLossStartsAtItsLevel) {
  o.residuals.robust_scale = 0.2f;
  auto backend = MakeCpuBackend({});
  std::vector<float> scales;
  HierarchyCallbacks cb;
  cb.level_started = [&](const HierarchyLevel&) { scales.push_back(backend->level().residuals.robust_scale); };
  SolveHierarchy(backend.get(), scene.geometry, views, o, {}, cb);
  EXPECT_EQ(scales, (std::vector<float>{0.f, 0.2f, 0.2f}));
  o.robust_from_level = 0;
  scales.clear();
  SolveHierarchy(backend.get(), scene.geometry, views, o, {}, cb);
  EXPECT_EQ(scales, (std::vector<float>{0.2f, 0.2f, 0.2f}));
}

TEST_F(HierarchyMemoryTest, LevelIterationsOverrideTheDefaultForTheLevelsGiven) {
  o.level_iterations = {2, 0};
  o.iterations = 3;
  std::vector<int> run;
  HierarchyCallbacks cb;
  cb.level_done = [&](const HierarchyLevel& h, const SolverSummary& s, const std::vector<float>&) {
    EXPECT_EQ(h.solver.max_iterations, o.IterationsAt(h.level));
    run.push_back(s.iterations);
  };
  SolveHierarchy(MakeCpuBackend({}).get(), scene.geometry, views, o, {}, cb);
  EXPECT_EQ(run, (std::vector<int>{2, 0, 3}));
}

}  // namespace
}  // namespace perf::recon
