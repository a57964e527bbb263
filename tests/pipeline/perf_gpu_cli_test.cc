// perf_gpu (pipeline/gpu_main.cc: perf reconstruct and render for a bare GPU machine, its images
// through libpng) against perf on the CPU: with the image pyramid off both fit the same checkpoint
// to the byte from the same workspace, so the GPU build trains on the very data perf does; with
// its area-average pyramid it still fits, and perf renders what perf_gpu fitted (a workspace
// crosses between the two). The device itself: bench/perf_gpu_dry_run.sh (CTest perf_gpu_dry_run).
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"
#include "workspace/image_io.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

std::string Bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

double TestPsnr(const fs::path& ws) {
  std::ifstream in(ws / "recon" / "recon.json");
  return nlohmann::json::parse(in)["test_psnr"].get<double>();
}

TEST(PerfGpuCli, FitsPerfsCheckpointOnTheCpuAndPerfReadsItsWorkspace) {
  test::TempDir dir;
  const fs::path a = dir / "perf", b = dir / "perf_gpu";
  test::MakeSyntheticWorkspace(dir.path(), a);
  fs::copy(a, b, fs::copy_options::recursive);
  const std::string perf = test::PerfBinary(), perf_gpu = std::string(PERF_BINARY_DIR) + "/perf_gpu";
  const std::string fit = " --device cpu -j 1 --levels 1 --start-resolution 8 --iterations 2 --no-grow-box -q";
  auto r = RunCommand(perf + " reconstruct " + a.string() + fit + " --no-pyramid");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunCommand(perf_gpu + " reconstruct " + b.string() + fit + " --no-pyramid");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string ckpt_a = Bytes(a / "recon" / "level_0.perfvol"), ckpt_b = Bytes(b / "recon" / "level_0.perfvol");
  ASSERT_GT(ckpt_a.size(), 1000u);
  EXPECT_TRUE(ckpt_a == ckpt_b) << "the same photos (PNG and RGBA alpha read by libpng as by OpenImageIO), the same fit";
  EXPECT_EQ(TestPsnr(a), TestPsnr(b));

  // Two levels with each one's image pyramid (perf_gpu: area averages, not OpenImageIO's filter).
  const std::string two = " --device cpu -j 1 --levels 2 --start-resolution 8 --iterations 2 --no-grow-box -q";
  r = RunCommand(perf + " reconstruct " + a.string() + two);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunCommand(perf_gpu + " reconstruct " + b.string() + two);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NEAR(TestPsnr(b), TestPsnr(a), 0.5);
  // perf renders perf_gpu's fit; perf_gpu's renders are what perf's would be.
  r = RunCommand(perf + " render " + b.string() + " --device cpu -j 1 --opacity -o " + (dir / "by_perf").string() + " -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunCommand(perf_gpu + " render " + b.string() + " --device cpu -j 1 --opacity -o " + (dir / "by_gpu").string() + " -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  int compared = 0;
  for (const auto& e : fs::directory_iterator(dir / "by_perf")) {
    const fs::path other = dir / "by_gpu" / e.path().filename();
    ASSERT_TRUE(fs::exists(other)) << other;
    EXPECT_EQ(ReadImage(other).pixels, ReadImage(e.path()).pixels) << e.path().filename();
    ++compared;
  }
  EXPECT_GE(compared, 2);
  // What perf_gpu leaves out is refused by name, not half run.
  r = RunCommand(perf_gpu + " reconstruct " + b.string() + " --view");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--view"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace perf
