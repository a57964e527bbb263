// `perf run` as a user runs it on a small synthetic capture (NeRF-style transforms.json): every
// stage runs, a second run skips them all, a newer input re-runs from import, other settings re-run
// the stages they shape; and a run stopped
// mid-reconstruction (Ctrl-C, or killed outright) resumes after the last checkpoint and ends
// with a complete workspace in which no file is damaged; a forced run that fails before its first
// level leaves the previous result as it was.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <nlohmann/json.hpp>
#include <thread>
#include <tuple>

#include "common/atomic_file.h"
#include "common/owned_files.h"
#include "recon_cuda/data/checkpoint.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"
#include "workspace/scene.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

class RunCli : public ::testing::Test {
 protected:
  void SetUp() override { test::MakeSyntheticWorkspace(dir_.path(), dir_ / "imported"); }
  // `perf run` on the synthetic scene into `ws`; Run: into ws_ with the preview preset.
  std::string RunIn(const fs::path& ws, const std::string& extra) {
    return test::PerfBinary() + " run --nerf " + (dir_ / "transforms.json").string() + " --workspace " + ws.string() +
           " " + extra;
  }
  std::string Run(const std::string& extra) { return RunIn(ws_, "--preset preview " + extra); }
  nlohmann::json RunJson() { return nlohmann::json::parse(ReadFileToString(ws_ / "run.json")); }
  // Every output is there and reads back: scene, checkpoints, manifests, report.
  void ExpectCompleteWorkspace(int levels) {
    EXPECT_NO_THROW(ReadScene(ws_ / "scene.json"));
    for (int k = 0; k < levels; ++k) EXPECT_NO_THROW(recon::ReadCheckpoint(recon::CheckpointPath(ws_, k))) << k;
    const nlohmann::json manifest = nlohmann::json::parse(ReadFileToString(ws_ / "export.json"));
    for (const auto& f : manifest["files"]) EXPECT_TRUE(fs::exists(ws_ / f.get<std::string>())) << f;
    EXPECT_EQ(manifest["checkpoint"], "recon/level_" + std::to_string(levels - 1) + ".perfvol");
    const nlohmann::json report = nlohmann::json::parse(ReadFileToString(ws_ / "report.json"));
    EXPECT_EQ(report["test_views"].size(), 3u);
    // No temporary files of interrupted atomic writes are left behind.
    for (const auto& e : fs::recursive_directory_iterator(ws_)) {
      EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
    }
  }
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

TEST_F(RunCli, RunsEveryStageThenSkipsWhatIsUpToDate) {
  auto r = RunCommand(Run("--levels 1 --iterations 3 --log-json " + (dir_ / "log.jsonl").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("preset preview"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Held-out views: PSNR"), std::string::npos) << r.output;
  ExpectCompleteWorkspace(1);
  const nlohmann::json initial = RunJson();  // kept: a range-for over a temporary's member dangles
  for (const auto& s : initial["stages"]) EXPECT_FALSE(s["skipped"].get<bool>()) << s;

  r = RunCommand(Run("--levels 1 --iterations 3 --log-json " + (dir_ / "log.jsonl").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json again = RunJson();
  ASSERT_EQ(again["stages"].size(), 4u);  // import, reconstruct, export, eval (no sfm from a json)
  for (const auto& s : again["stages"]) EXPECT_TRUE(s["skipped"].get<bool>()) << s;
  const std::string log = ReadFileToString(dir_ / "log.jsonl");
  EXPECT_NE(log.find("\"event\":\"skipped\""), std::string::npos);
  EXPECT_NE(log.find("\"event\":\"iteration\""), std::string::npos);

  // A newer input: import and everything after it run again.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  fs::last_write_time(dir_ / "transforms.json", fs::file_time_type::clock::now());
  r = RunCommand(Run("--levels 1 --iterations 3 --log-level quiet"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output, "") << "quiet prints nothing";
  const nlohmann::json fresh = RunJson();
  for (const auto& s : fresh["stages"]) EXPECT_FALSE(s["skipped"].get<bool>()) << s;

  // Bad command lines are named.
  r = RunCommand(test::PerfBinary() + " run --workspace " + ws_.string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--images"), std::string::npos) << r.output;
  for (const std::string bad : {"--preset fast", "--sh-degree 3", "--sh-from-level -6", "--cost-tolerance 1"}) {
    r = RunCommand(RunIn(ws_, bad));
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find(bad.substr(0, bad.find(' '))), std::string::npos) << r.output;
  }
}

// Every preset solves view-dependent colour (preview and high at their last level, default from
// level 2, or the last when there are fewer), and --sh-degree and --sh-from-level override the
// preset's.
TEST_F(RunCli, PresetsSolveViewDependence) {
  // A quick run of every stage again with `extra`: what it printed and its recon.json.
  const auto run = [&](const std::string& extra) {
    const auto r = RunCommand(RunIn(ws_, "--max-size 24 --force " + extra));
    EXPECT_EQ(r.exit_code, 0) << extra << ": " << r.output;
    return std::pair{r.output, nlohmann::json::parse(ReadFileToString(ws_ / "recon" / "recon.json"))};
  };
  const auto sh_degree = [&](const std::string& extra) {
    const auto [output, recon] = run("--levels 1 --iterations 2 " + extra);
    const bool said = output.find("view-dependent colour (degree 1)") != std::string::npos;
    const int degree = recon["sh_degree"];
    EXPECT_EQ(said, degree == 1) << extra << ": " << output;
    return degree;
  };
  EXPECT_EQ(sh_degree("--preset high"), 1);
  EXPECT_EQ(sh_degree("--preset high --sh-degree 0"), 0);
  EXPECT_EQ(sh_degree("--preset default"), 1);
  EXPECT_EQ(sh_degree("--preset default --sh-degree 0"), 0);
  EXPECT_EQ(sh_degree("--preset preview"), 1);
  EXPECT_EQ(sh_degree("--preset preview --sh-degree 0"), 0);
  // The level the bands join (recon.json's is 1-based): the default preset's level 2 (with one
  // level, the sh_degree cases above, the last), the preview preset's the last, or --sh-from-level's.
  const auto from_level = [&](const std::string& extra, const std::string& said) {
    const auto [output, recon] = run("--levels 2 --iterations 1 " + extra);
    EXPECT_NE(output.find("view-dependent colour (degree 1) " + said), std::string::npos) << extra << ": " << output;
    return recon["sh_from_level"].get<int>();
  };
  EXPECT_EQ(from_level("--preset default", "from level 2"), 2);
  EXPECT_EQ(from_level("--preset preview", "at the last level"), 2);
  EXPECT_EQ(from_level("--preset preview --sh-from-level -1", "at the last 2 levels"), 1);
  EXPECT_EQ(from_level("--preset default --sh-from-level 1", "from level 1"), 1);
  // A level past the preset's set ones is refused before anything is written.
  const fs::path fresh = dir_ / "never_written";
  const auto r = RunCommand(RunIn(fresh, "--preset preview --sh-from-level 3"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("past the last of the 2 levels"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(fresh)) << r.output;
}

// A run whose settings differ from the workspace's runs the stages they shape again, and says
// why: before, an up-to-date workspace kept the earlier run's photos, fit and orbit whatever the
// preset or the options asked for.
TEST_F(RunCli, ChangedSettingsRunTheStagesTheyShape) {
  const auto stages = [&](const std::string& extra) {
    const auto r = RunCommand(Run("--levels 1 --iterations 2 " + extra));
    EXPECT_EQ(r.exit_code, 0) << extra << ": " << r.output;
    std::map<std::string, std::pair<bool, std::string>> s;  // stage: skipped, reason
    const nlohmann::json run = RunJson();
    for (const auto& st : run["stages"]) {
      s[st["stage"].get<std::string>()] = {st["skipped"].get<bool>(), st["reason"].get<std::string>()};
    }
    return std::pair{r.output, s};
  };
  stages("--max-size 24");
  auto [output, s] = stages("--max-size 24 --sh-degree 0");
  EXPECT_TRUE(s["import"].first) << output;
  EXPECT_FALSE(s["reconstruct"].first) << output;
  EXPECT_NE(s["reconstruct"].second.find("sh_degree 1 -> 0"), std::string::npos) << s["reconstruct"].second;
  EXPECT_NE(output.find("fitting from the start: the checkpoints' settings differ from this run's (sh_degree 1 -> 0)"),
            std::string::npos) << output;
  EXPECT_EQ(nlohmann::json::parse(ReadFileToString(ws_ / "recon" / "recon.json"))["sh_degree"], 0);
  EXPECT_FALSE(s["export"].first) << "a new fit is exported";

  std::tie(output, s) = stages("--max-size 24 --sh-degree 0");  // the same again: nothing to do
  for (const auto& [name, st] : s) EXPECT_TRUE(st.first) << name << ": " << st.second;

  // Another photo size: imported again (the old scene.json said nothing, and the fit went on at 24 px).
  std::tie(output, s) = stages("--max-size 16 --sh-degree 0");
  EXPECT_FALSE(s["import"].first) << output;
  EXPECT_NE(output.find("photos of at most 24 px, this run asks for at most 16 px: importing again"), std::string::npos)
      << output;
  const Scene scene = ReadScene(ws_ / "scene.json");
  EXPECT_EQ(scene.source.max_size, 16);
  EXPECT_LE(std::max(scene.cameras.front().width, scene.cameras.front().height), 16);
  EXPECT_FALSE(s["reconstruct"].first) << output;

  // A photo left out by hand in scene.json: the edit is the user's, so an import that would replace
  // it is refused, naming the photo; with the edited file moved away, the import goes on.
  nlohmann::json edited = nlohmann::json::parse(ReadFileToString(ws_ / "scene.json"));
  const std::string by_hand = edited["images"][0]["name"];
  edited["images"][0]["split"] = "excluded";
  WriteFileAtomically(ws_ / "scene.json", edited.dump());
  auto refused = RunCommand(Run("--levels 1 --iterations 2 --max-size 12 --sh-degree 0"));
  EXPECT_EQ(refused.exit_code, 2) << refused.output;
  EXPECT_NE(refused.output.find("it leaves out " + by_hand + " by hand"), std::string::npos) << refused.output;
  EXPECT_EQ(ReadFileToString(ws_ / "scene.json"), edited.dump());
  fs::rename(ws_ / "scene.json", dir_ / "scene.hand.json");
  std::tie(output, s) = stages("--max-size 16 --sh-degree 0");
  EXPECT_FALSE(s["import"].first) << output;

  // The export of another orbit (a preset's frame count) is made again.
  nlohmann::json manifest = nlohmann::json::parse(ReadFileToString(ws_ / "export.json"));
  manifest["renders"]["orbit"] = manifest["renders"]["orbit"].get<int>() + 1;
  UseOwnershipRecord(ws_);  // written as a perf would have: the test stands in for an older run's settings
  WriteFileAtomically(ws_ / "export.json", manifest.dump());
  DropOwnershipRecord();
  std::tie(output, s) = stages("--max-size 16 --sh-degree 0");
  EXPECT_TRUE(s["reconstruct"].first) << output;
  EXPECT_FALSE(s["export"].first) << output;

  // Checkpoints whose settings were not recorded (an older perf's) are fitted again.
  fs::remove(ws_ / "recon" / "settings.json");
  std::tie(output, s) = stages("--max-size 16 --sh-degree 0");
  EXPECT_FALSE(s["reconstruct"].first) << output;
  EXPECT_NE(output.find("fitting from the start: the checkpoints' settings are not recorded"), std::string::npos) << output;
  EXPECT_TRUE(fs::exists(ws_ / "recon" / "settings.json"));
}

// A COLMAP capture whose photo was replaced after the import is imported again (before, only the
// model folder's files were compared with scene.json).
TEST(RunCliColmap, APhotoChangedSinceTheImportImportsAgain) {
  test::TempDir dir;
  fs::copy(fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini", dir / "capture", fs::copy_options::recursive);
  const std::string cmd = test::PerfBinary() + " run --colmap " + (dir / "capture" / "sparse" / "0").string() +
                          " --images " + (dir / "capture" / "images").string() + " --workspace " +
                          (dir / "ws").string() + " --preset preview --max-size 24 --levels 1 --iterations 1";
  const auto import_skipped = [&] {
    const auto r = RunCommand(cmd);
    EXPECT_EQ(r.exit_code, 0) << r.output;
    const nlohmann::json run = nlohmann::json::parse(ReadFileToString(dir / "ws" / "run.json"));
    return run["stages"][0]["skipped"].get<bool>();
  };
  EXPECT_FALSE(import_skipped());
  EXPECT_TRUE(import_skipped());
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  fs::last_write_time(dir / "capture" / "images" / "DSCF5614.JPG", fs::file_time_type::clock::now());
  EXPECT_FALSE(import_skipped());
}

// Stops `perf run` with `sig` once level 0's checkpoint is written (the solve is then inside level 1).
int StopDuringLevel1(const std::string& command, const fs::path& ws, int sig) {
  return test::StopWhenExists(command, recon::CheckpointPath(ws, 0), sig);
}

TEST_F(RunCli, CtrlCStopsCleanlyAndTheNextRunResumes) {
  const std::string cmd = Run("--levels 2 --iterations 60");
  const int status = StopDuringLevel1(cmd, ws_, SIGINT);
  ASSERT_TRUE(WIFEXITED(status)) << "Ctrl-C should stop perf at a safe point, not kill it";
  EXPECT_EQ(WEXITSTATUS(status), 130);
  EXPECT_TRUE(fs::exists(recon::CheckpointPath(ws_, 0)));
  EXPECT_FALSE(fs::exists(recon::CheckpointPath(ws_, 1))) << "stopped too late to test anything";
  const auto r = RunCommand(cmd);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("resuming after level 0"), std::string::npos) << r.output;
  ExpectCompleteWorkspace(2);
}

// Without the preview's view dependence (the Ctrl-C case above resumes into a level with bands):
// its last level then takes a quarter of the time.
TEST_F(RunCli, KilledMidReconstructionResumesWithNoDamagedFile) {
  const std::string cmd = Run("--levels 2 --iterations 60 --sh-degree 0");
  const int status = StopDuringLevel1(cmd, ws_, SIGKILL);
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_FALSE(fs::exists(recon::CheckpointPath(ws_, 1))) << "killed too late to test anything";
  const auto r = RunCommand(cmd);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("resuming after level 0"), std::string::npos) << r.output;
  ExpectCompleteWorkspace(2);
  const nlohmann::json run = RunJson();
  EXPECT_TRUE(run["stages"][0]["skipped"].get<bool>()) << "import was complete before the kill";
}

// --force starts the reconstruction over, but the last good result stays until the new run has a
// level of its own (recon/previous/ holds it meanwhile): stopped before, the result is as it was.
TEST_F(RunCli, ForcedRunStoppedBeforeItsFirstLevelLeavesThePreviousResult) {
  auto r = RunCommand(Run("--levels 1 --iterations 3"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const fs::path level0 = recon::CheckpointPath(ws_, 0), summary = ws_ / "recon" / "recon.json",
                 settings = ws_ / "recon" / "settings.json";
  const std::string checkpoint = ReadFileToString(level0), recon_json = ReadFileToString(summary),
                    settings_json = ReadFileToString(settings);

  const int status =
      test::StopWhenExists(Run("--force --levels 1 --iterations 400"), ws_ / "recon" / "previous", SIGINT);
  ASSERT_TRUE(WIFEXITED(status)) << "Ctrl-C should stop perf at a safe point, not kill it";
  EXPECT_EQ(WEXITSTATUS(status), 130);
  ASSERT_TRUE(fs::exists(level0)) << "the forced run destroyed the last good result";
  EXPECT_EQ(ReadFileToString(level0), checkpoint) << "stopped too late to test anything, or the result changed";
  EXPECT_EQ(ReadFileToString(summary), recon_json);
  EXPECT_EQ(ReadFileToString(settings), settings_json) << "the record must be the checkpoints' (3 iterations, not 400)";
  EXPECT_FALSE(fs::exists(ws_ / "recon" / "previous"));
  EXPECT_TRUE(fs::exists(ws_ / "export.json"));
}

}  // namespace
}  // namespace perf
