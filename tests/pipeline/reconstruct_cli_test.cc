// `perf reconstruct` and `perf render` as a user runs them, on a small synthetic capture written
// as a NeRF-style transforms.json: outputs, log, checkpoints, resume, previews, renders, and the
// bad inputs (no import yet, unknown options, a damaged checkpoint).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/reconstruct_options.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"
#include "workspace/image_io.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

std::vector<nlohmann::json> ReadLog(const fs::path& path) {
  std::vector<nlohmann::json> lines;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

class ReconstructCli : public ::testing::Test {
 protected:
  void SetUp() override { test::MakeSyntheticWorkspace(dir_.path(), ws_); }
  std::string Perf(const std::string& args) { return test::PerfBinary() + " " + args; }
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

TEST_F(ReconstructCli, ReconstructsLogsCheckpointsResumesAndRenders) {
  // --no-grow-box: at 8^3 after 4 iterations the synthetic scene's first level reaches the box's
  // sides and would be fitted again in a grown box (box_check.h); this test counts its iterations.
  auto r = RunCommand(Perf("reconstruct " + ws_.string() +
                           " --levels 2 --start-resolution 8 --iterations 4 --preview-every 2 --eval-every 2"
                           " --no-grow-box"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("backend: cpu"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("level 2/2"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("held-out PSNR"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(ws_ / "recon" / "level_0.perfvol"));
  EXPECT_TRUE(fs::exists(ws_ / "recon" / "level_1.perfvol"));
  EXPECT_TRUE(fs::exists(ws_ / "preview" / "recon_l1_i4.png"));

  const std::vector<nlohmann::json> log = ReadLog(ws_ / "recon" / "log.jsonl");
  int iterations = 0, levels = 0, with_test = 0;
  double first_cost = 0, last_cost = 0;
  for (const auto& j : log) {
    if (j["event"] == "iteration") {
      ++iterations;
      for (const char* k : {"level", "cost", "train_psnr", "cg_iterations", "step", "seconds", "elapsed"}) {
        EXPECT_TRUE(j.contains(k)) << k << " in " << j.dump();
      }
      EXPECT_TRUE(j["seconds"].contains("linearize"));
      if (j.contains("test_psnr")) ++with_test;
      if (iterations == 1) first_cost = j["cost"];
      last_cost = j["cost_after"];
    }
    levels += j["event"] == "level";
  }
  EXPECT_EQ(iterations, 8);
  EXPECT_EQ(levels, 2);
  EXPECT_EQ(with_test, 4);
  EXPECT_LT(last_cost, 0.5 * first_cost);

  const nlohmann::json summary = nlohmann::json::parse(std::ifstream(ws_ / "recon" / "recon.json"));
  EXPECT_EQ(summary["final_checkpoint"], "recon/level_1.perfvol");
  EXPECT_GT(summary["test_psnr"].get<double>(), 15.0);
  EXPECT_EQ(summary["min_box_opacity"].get<double>(), 0.0);  // scored as fitted, without the paper's rule
  // Photos without alpha: the shells are learned, and both smoothness terms are on by default.
  EXPECT_EQ(summary["background"], "learned");
  EXPECT_EQ(summary["smooth_grid"].get<double>(), 0.3);
  EXPECT_EQ(summary["smooth_shells"].get<double>(), 0.1);
  EXPECT_EQ(summary["cost_tolerance"].get<double>(), recon::kDefaultCostTolerance);
  // View-dependent colour of degree 1 by default, at the last level alone.
  EXPECT_EQ(recon::ReadCheckpoint(recon::CheckpointPath(ws_, 0)).shape.sh_degree, 0);
  EXPECT_EQ(recon::ReadCheckpoint(recon::CheckpointPath(ws_, 1)).shape.sh_degree, 1);

  // Everything done: --resume says so and changes nothing.
  const auto before = fs::last_write_time(ws_ / "recon" / "level_1.perfvol");
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 2 --start-resolution 8 --resume"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("already complete"), std::string::npos) << r.output;
  EXPECT_EQ(fs::last_write_time(ws_ / "recon" / "level_1.perfvol"), before);

  r = RunCommand(Perf("render " + ws_.string() + " --opacity"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("mean PSNR"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(ws_ / "renders" / "view0.png"));
  EXPECT_TRUE(fs::exists(ws_ / "renders" / "view0_opacity.png"));
  const ImageInfo info = ReadImageInfo(ws_ / "renders" / "view6.png");
  EXPECT_EQ(info.width, 32);

  // By default the render is the volume as fitted; the rule blanks rays whose box opacity is below
  // its threshold (1: every ray, since the box's opacity is below 1 along each).
  r = RunCommand(Perf("render " + ws_.string() + " --min-box-opacity 0 -o " + (ws_ / "rule0").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunCommand(Perf("render " + ws_.string() + " --min-box-opacity 1 -o " + (ws_ / "rule1").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::vector<float> fitted = ReadImage(ws_ / "renders" / "view0.png").pixels;
  EXPECT_EQ(fitted, ReadImage(ws_ / "rule0" / "view0.png").pixels);
  EXPECT_NE(fitted, ReadImage(ws_ / "rule1" / "view0.png").pixels);
}

// Without --levels the photos choose: the fewest levels reaching one cell a pixel, within
// --max-resolution; the run says so and recon.json records it.
TEST_F(ReconstructCli, LevelsFollowThePhotosWithinTheCap) {
  auto r = RunCommand(Perf("reconstruct " + ws_.string() + " --start-resolution 4 --max-resolution 8 --iterations 1"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("levels: 2 (4^3 to 8^3) chosen from the photos"), std::string::npos) << r.output;
  const nlohmann::json summary = nlohmann::json::parse(std::ifstream(ws_ / "recon" / "recon.json"));
  EXPECT_EQ(summary["levels_chosen"], "from the photos");
  EXPECT_EQ(summary["max_resolution"], 8);
  EXPECT_GT(summary["pixels_across_box"].get<double>(), 8.0);  // so the cap, not the photos, chose 2 levels
  EXPECT_EQ(summary["levels"], 2);
  EXPECT_EQ(summary["final_checkpoint"], "recon/level_1.perfvol");
  EXPECT_NE(r.output.find("--max-resolution 8 stops short of"), std::string::npos) << r.output;

  r = RunCommand(Perf("reconstruct " + ws_.string() + " --start-resolution 8 --max-resolution 4"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--max-resolution"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("at least --start-resolution (8)"), std::string::npos) << r.output;
  EXPECT_EQ(summary["robust_scale"], 0.0);  // least squares unless asked

  for (const char* bad : {"-1", "inf"}) {
    r = RunCommand(Perf("reconstruct " + ws_.string() + " --robust " + bad));
    EXPECT_EQ(r.exit_code, 2) << r.output;
    EXPECT_NE(r.output.find(std::string("--robust = ") + bad + ": must be >= 0"), std::string::npos) << r.output;
  }
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --robust nan"));  // refused as every option's NaN is
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--robust: nan is not a number"), std::string::npos) << r.output;
}

TEST_F(ReconstructCli, ResumeContinuesAfterTheLastLevel) {
  auto r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 8 --iterations 2"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(ws_ / "recon" / "level_1.perfvol"));
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 2 --start-resolution 8 --iterations 2 --resume"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("resuming after level 0"), std::string::npos) << r.output;
  // An explicit --resume goes on with other settings (here a level more), and names them.
  EXPECT_NE(r.output.find("resuming although the checkpoints' settings differ from this run's (levels 1 -> 2); the "
                          "levels done keep theirs"),
            std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(ws_ / "recon" / "level_1.perfvol"));
  const std::vector<nlohmann::json> log = ReadLog(ws_ / "recon" / "log.jsonl");
  int resumes = 0, iterations = 0;
  for (const auto& j : log) {
    resumes += j["event"] == "resume";
    iterations += j["event"] == "iteration";
  }
  EXPECT_EQ(resumes, 1);
  EXPECT_EQ(iterations, 4);  // the first run's 2 kept, then level 1's 2
  // Resuming with another start resolution would mix two hierarchies: refused.
  fs::remove(ws_ / "recon" / "level_1.perfvol");
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 2 --start-resolution 16 --resume"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("level_0.perfvol"), std::string::npos) << r.output;
}

// A workspace whose levels were fitted without view dependence (an earlier build's default): a
// resume at today's default names the change and solves the bands at the level it adds.
TEST_F(ReconstructCli, ResumeAtTheDefaultAddsBandsToTheLevelsLeft) {
  auto r = RunCommand(
      Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 8 --iterations 1 --sh-degree 0"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 2 --start-resolution 8 --iterations 1 --resume"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("sh_degree 0 -> 1"), std::string::npos) << r.output;
  EXPECT_EQ(recon::ReadCheckpoint(recon::CheckpointPath(ws_, 0)).shape.sh_degree, 0);
  EXPECT_EQ(recon::ReadCheckpoint(recon::CheckpointPath(ws_, 1)).shape.sh_degree, 1);
}

// The shells of a checkpoint: (min, max) over every shell parameter (not the bands, exposures or
// poses that follow them).
std::pair<float, float> ShellRange(const fs::path& checkpoint) {
  const recon::Checkpoint c = recon::ReadCheckpoint(checkpoint);
  float lo = 1e30f, hi = -1e30f;
  for (int64_t i = c.shape.GridParamCount(); i < c.shape.ShStart(); ++i) {
    lo = std::min(lo, c.params[i]);
    hi = std::max(hi, c.params[i]);
  }
  return {lo, hi};
}

TEST_F(ReconstructCli, BackgroundIsLearnedOrFixed) {
  // These photos had no alpha: auto learns the shells.
  auto r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 1 --start-resolution 8 --iterations 2"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("background: learned"), std::string::npos) << r.output;
  auto range = ShellRange(ws_ / "recon" / "level_0.perfvol");
  EXPECT_LT(range.first, 0.9f);
  nlohmann::json summary = nlohmann::json::parse(std::ifstream(ws_ / "recon" / "recon.json"));
  EXPECT_EQ(summary["background"], "learned");
  EXPECT_EQ(summary["opacity_residual"], "auxiliary");  // no alpha to fit

  // Fixed: every shell texel stays scene.json's background (white, opaque) through two levels.
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 2 --start-resolution 8 --iterations 2 "
                      "--background fixed"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("background: fixed at (1, 1, 1)"), std::string::npos) << r.output;
  for (int level : {0, 1}) {
    range = ShellRange(recon::CheckpointPath(ws_, level));
    EXPECT_EQ(range.first, 1.f) << level;
    EXPECT_EQ(range.second, 1.f) << level;
  }
  summary = nlohmann::json::parse(std::ifstream(ws_ / "recon" / "recon.json"));
  EXPECT_EQ(summary["background"], "fixed");

  // Resuming a learned-shell level with a fixed background resets the shells to it.
  r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 8 --iterations 2"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_LT(ShellRange(ws_ / "recon" / "level_0.perfvol").first, 0.9f);
  r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 2 --start-resolution 8 --iterations 2 --resume "
                      "--background fixed"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  range = ShellRange(ws_ / "recon" / "level_1.perfvol");
  EXPECT_EQ(range.first, 1.f);
  EXPECT_EQ(range.second, 1.f);

  r = RunCommand(Perf("reconstruct " + ws_.string() + " --background sky"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--background"), std::string::npos) << r.output;
}

// Both solvers start from the same opacity (each measured best there) unless one is given.
TEST_F(ReconstructCli, StartOpacityIsTheSameForBothSolvers) {
  const auto start_of = [&](const std::string& flags) {
    const auto r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 8 --iterations 1 " +
                                   flags));
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return nlohmann::json::parse(std::ifstream(ws_ / "recon" / "recon.json"))["init_opacity"].get<double>();
  };
  EXPECT_DOUBLE_EQ(start_of(""), 0.99);
  EXPECT_DOUBLE_EQ(start_of("--solver adam"), 0.99);
  EXPECT_DOUBLE_EQ(start_of("--solver adam --init-opacity 0.5"), 0.5);
  EXPECT_DOUBLE_EQ(start_of("--init-opacity 0.3"), 0.3);
}

TEST_F(ReconstructCli, BadInputsAreNamed) {
  // A damaged checkpoint is refused on resume, naming the file; nothing else is written.
  auto r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 8 --iterations 1"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const fs::path ck = ws_ / "recon" / "level_0.perfvol";
  fs::resize_file(ck, fs::file_size(ck) - 10);
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 2 --start-resolution 8 --resume"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("level_0.perfvol"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("truncated"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(ws_ / "recon" / "level_1.perfvol"));
  r = RunCommand(Perf("render " + ws_.string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;

  // Each bad value is refused (exit 2) naming its option.
  for (const std::string choice : {"--solver sgd", "--device tpu", "--background sky", "--device CPU", "--levels 9",
                                   "--smooth-shells -1", "--smooth-grid inf", "--init-opacity 1", "--lambda inf",
                                   "--alpha-weight inf", "--lr-density inf", "--sh-from-level 7", "--sh-from-level -6",
                                   "--cost-tolerance -0.1"}) {
    r = RunCommand(Perf("reconstruct " + ws_.string() + " " + choice));
    EXPECT_EQ(r.exit_code, 2) << choice << ": " << r.output;
    EXPECT_NE(r.output.find(choice.substr(0, choice.find(' '))), std::string::npos) << r.output;
  }
  // A preview photo that is not in the capture is named before anything is written.
  const std::string log_before = ReadFileToString(ws_ / "recon" / "log.jsonl");
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 1 --start-resolution 8 --view-image nosuch.png"));
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("--view-image"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("nosuch.png"), std::string::npos) << r.output;
  EXPECT_EQ(ReadFileToString(ws_ / "recon" / "log.jsonl"), log_before);
  // Bands from a level past the set ones would be no bands at all: refused before anything runs.
  r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 2 --start-resolution 8 --sh-degree 1 --sh-from-level 3"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("past the last of the 2 levels"), std::string::npos) << r.output;
  EXPECT_EQ(ReadFileToString(ws_ / "recon" / "log.jsonl"), log_before);
  r = RunCommand(Perf("render " + ws_.string() + " --split val"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--split"), std::string::npos) << r.output;
  r = RunCommand(Perf("render " + ws_.string() + " --view nosuch.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = RunCommand(Perf("render " + ws_.string() + " --min-box-opacity 1.5"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--min-box-opacity"), std::string::npos) << r.output;
  r = RunCommand(Perf("render " + ws_.string() + " --min-box-opacity abc"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
}

TEST(ReconstructCliPlain, NoWorkspaceYet) {
  test::TempDir dir;
  auto r = RunCommand(test::PerfBinary() + " reconstruct " + dir.path().string());
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("scene.json"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("perf import"), std::string::npos) << r.output;
  r = RunCommand(test::PerfBinary() + " render " + dir.path().string());
  EXPECT_EQ(r.exit_code, 3) << r.output;
}

}  // namespace
}  // namespace perf
