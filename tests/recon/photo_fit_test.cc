// The photo-fit check (recon_cuda/run/photo_fit.h): the rule on given PSNRs, and on a known scene a
// training photo that does not belong to its pose is the one named.
#include "recon_cuda/run/photo_fit.h"

#include <gtest/gtest.h>

#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/run/evaluation.h"
#include "tests/recon/synthetic_scene.h"

namespace perf::recon {
namespace {

TEST(PhotoFit, PhotosMoreThanTheMarginBelowTheMedianAreNamedWorstFirst) {
  // Median 24 (the middle of seven); margin 4: below 20 is poor, 20 itself is not.
  const PhotoFits f =
      FindPoorFits({{"a", 24}, {"b", 17.5}, {"c", 25}, {"d", 20}, {"e", 19.9}, {"f", 26}, {"g", 27}});
  EXPECT_DOUBLE_EQ(f.median_psnr, 24);
  ASSERT_EQ(f.poor.size(), 2u);
  EXPECT_EQ(f.poor[0].name, "b");
  EXPECT_EQ(f.poor[1].name, "e");
  const std::string w = f.Warning();
  EXPECT_NE(w.find("2 training photos fit more than 4 dB worse than the median photo (24.0 dB)"), std::string::npos) << w;
  EXPECT_NE(w.find("b 17.5 dB, e 19.9 dB"), std::string::npos) << w;
  // An even count takes the mean of the middle two; a wider margin names fewer.
  const PhotoFits even = FindPoorFits({{"a", 20}, {"b", 22}, {"c", 26}, {"d", 30}}, {.max_db_below_median = 3});
  EXPECT_DOUBLE_EQ(even.median_psnr, 24);
  ASSERT_EQ(even.poor.size(), 1u);
  EXPECT_EQ(even.poor[0].name, "a");
  const nlohmann::json j = f.ToJson();
  EXPECT_DOUBLE_EQ(j["median_psnr"].get<double>(), 24);
  ASSERT_EQ(j["poor"].size(), 2u);
  EXPECT_EQ(j["poor"][0]["name"], "b");
  EXPECT_DOUBLE_EQ(j["poor"][1]["psnr"].get<double>(), 19.9);
  EXPECT_TRUE(FindPoorFits({{"a", 24}, {"b", 25}, {"c", 26}}).Warning().empty());
  EXPECT_TRUE(FindPoorFits({{"a", 10}, {"b", 30}}).poor.empty());  // too few photos to tell
}

TEST(PhotoFit, ATrainingPhotoThatShowsAnotherViewIsNamed) {
  // The truth fits every photo but the one given another view's picture.
  test::SyntheticScene scene(16, 8, 12, 24, 100);  // view 0 held out, 11 training photos
  ASSERT_EQ(scene.train.size(), 11u);
  scene.train[4].image = scene.train[9].image;
  std::vector<std::string> names;
  for (const PosedImage& im : scene.train) names.push_back(im.name);
  const RaySet rays = MakeRaySet(scene.train);
  auto backend = MakeCpuBackend({});
  backend->SetLevel(LevelProblem{scene.shape, scene.geometry, &rays, {}}, 1);
  backend->Upload(0, scene.truth);
  SingleProcess comm;
  const PhotoFits f = CheckPhotoFits(backend.get(), 0, scene.train, names, {}, comm);
  ASSERT_EQ(f.poor.size(), 1u);
  EXPECT_EQ(f.poor[0].name, scene.train[4].name);
  EXPECT_GT(f.median_psnr, 30.0);  // the others: the truth, up to the photos' 4 x 4 sub-pixel average
  EXPECT_LT(f.poor[0].psnr, f.median_psnr - 10);
}

}  // namespace
}  // namespace perf::recon
