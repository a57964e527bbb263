// Resources as a hostile input or a tight machine meets them: a small file that decodes to
// gigabytes is refused, naming it, before it is decoded, within the process's memory limit.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <vector>

#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

// A PNG of `side` x `side` black pixels, written a row at a time (a few hundred KB on disk).
void WriteBlackPng(const fs::path& path, int side) {
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(side, side, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("png:compressionLevel", 1);
  ASSERT_TRUE(out->open(path.string(), spec));
  const std::vector<unsigned char> row(static_cast<size_t>(side) * 3, 0);
  for (int y = 0; y < side; ++y) ASSERT_TRUE(out->write_scanline(y, 0, OIIO::TypeDesc::UINT8, row.data()));
  ASSERT_TRUE(out->close());
}

// 12000 x 12000 decodes to 1.7 GB of floats (three copies in flight on import); under a 4 GB
// address-space limit the import refuses it at once by name, instead of decoding it and failing
// in the allocator (or swapping) without a word about which photo.
TEST(ResourcesCli, APngBombIsRefusedBeforeDecodingWithinTheMemoryLimit) {
  test::TempDir dir;
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "ulimit -v cannot hold AddressSanitizer's shadow memory (perf -DPERF_SANITIZE=ON)";
#endif
  const fs::path bomb = dir / "bomb.png";
  WriteBlackPng(bomb, 12000);
  ASSERT_LT(fs::file_size(bomb), 4u << 20);
  const nlohmann::json transforms{
      {"camera_angle_x", 0.7},
      {"frames", {{{"file_path", "./bomb"}, {"transform_matrix", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 4}, {0, 0, 0, 1}}}}}}};
  std::ofstream(dir / "transforms.json") << transforms.dump();
  const auto start = std::chrono::steady_clock::now();
  const auto r = RunCommand("bash -c \"ulimit -v 4000000; exec timeout 120 " + test::PerfBinary() + " import -q --nerf " +
                            (dir / "transforms.json").string() + " --box-center 0 0 0 --box-size 1 1 1 --workspace " +
                            (dir / "ws").string() + "\"");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(r.exit_code, 5) << r.output;
  EXPECT_NE(r.output.find("bomb.png"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("not enough memory"), std::string::npos) << r.output;
  EXPECT_LT(seconds, 10) << "decoded before it was refused?";
  EXPECT_FALSE(fs::exists(dir / "ws"));
}

}  // namespace
}  // namespace perf
