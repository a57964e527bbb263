// Which level a workspace's outputs come from: a finer level that scored worse on the held-out
// views than a coarser one is not final (FinalLevelIndex), and export, eval and render find the
// level the run chose through recon.json, only while that record is the newest run's
// (FinalCheckpointPath).
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "common/atomic_file.h"
#include "recon_cuda/data/checkpoint.h"
#include "recon_cuda/run/reconstruct.h"
#include "recon_cuda/run/render_views.h"
#include "tests/test_util.h"

namespace perf::recon {
namespace {

namespace fs = std::filesystem;

std::vector<LevelReport> Scored(std::initializer_list<double> psnr) {
  std::vector<LevelReport> levels;
  int k = 0;
  for (double p : psnr) {
    LevelReport l;
    l.level = k++;
    l.test_psnr = p;
    levels.push_back(l);
  }
  return levels;
}

TEST(FinalLevel, AFinerLevelThatScoresWorseIsNotFinal) {
  EXPECT_EQ(FinalLevelIndex(Scored({19.5, 19.9, 21.2}), true), 2);
  EXPECT_EQ(FinalLevelIndex(Scored({19.5, 19.91, 19.47}), true), 1);  // issue 64's capture
  EXPECT_EQ(FinalLevelIndex(Scored({20.5, 19.9, 19.8}), true), 0);
  EXPECT_EQ(FinalLevelIndex(Scored({20.0, 20.0}), true), 1);   // the finer of equals
  EXPECT_EQ(FinalLevelIndex(Scored({20.5, 19.9}), false), 1);  // no held-out views: the last
  EXPECT_EQ(FinalLevelIndex({}, true), -1);
}

void Touch(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

TEST(FinalLevel, TheOutputsFollowTheRecordOfTheNewestRun) {
  test::TempDir dir;
  const fs::path ws = dir.path();
  EXPECT_TRUE(FinalCheckpointPath(ws).empty());
  Touch(CheckpointPath(ws, 0), "0");
  Touch(CheckpointPath(ws, 1), "1");
  EXPECT_EQ(FinalCheckpointPath(ws), CheckpointPath(ws, 1));  // no record: the finest
  const auto later = fs::last_write_time(CheckpointPath(ws, 1)) + std::chrono::seconds(2);
  Touch(ws / "recon" / "recon.json", R"({"final_checkpoint": "recon/level_0.perfvol"})");
  fs::last_write_time(ws / "recon" / "recon.json", later);
  EXPECT_EQ(FinalCheckpointPath(ws), CheckpointPath(ws, 0));
  // A newer level than the record (a later run that has not finished): the newest level.
  Touch(CheckpointPath(ws, 2), "2");
  fs::last_write_time(CheckpointPath(ws, 2), later + std::chrono::seconds(2));
  EXPECT_EQ(FinalCheckpointPath(ws), CheckpointPath(ws, 2));
  // A record naming anything but a level file of the workspace is not followed.
  for (const char* named : {"../../etc/passwd", "recon/level_7.perfvol", "scene.json"}) {
    Touch(ws / "recon" / "recon.json", std::string(R"({"final_checkpoint": ")") + named + "\"}");
    fs::last_write_time(ws / "recon" / "recon.json", later + std::chrono::seconds(4));
    EXPECT_EQ(FinalCheckpointPath(ws), CheckpointPath(ws, 2)) << named;
  }
}

}  // namespace
}  // namespace perf::recon
