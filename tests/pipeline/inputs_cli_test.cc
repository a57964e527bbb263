// The second reliability pass as a careless user (or an attacker) meets it on the command line:
// inputs are never written over, moved or removed, in any command after import either; nothing
// hangs on a FIFO or a device; every bad end is an exit code with a message naming the file.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <thread>

#include "common/atomic_file.h"
#include "common/workspace_lock.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using test::RunCommand;

// A command that would hang is stopped after a minute (exit 124), so a hang fails the test.
std::string Perf(const std::string& args) { return "timeout 60 " + test::PerfBinary() + " " + args; }


class InputsCli : public ::testing::Test {
 protected:
  void SetUp() override { test::MakeSyntheticWorkspace(dir_.path(), ws_); }
  void Reconstruct(const fs::path& ws) {
    const auto r = RunCommand(Perf("reconstruct -q " + ws.string() + " --levels 1 --start-resolution 8 --iterations 1"));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  // transforms.json with every frame's path made absolute (so the json can live anywhere).
  json AbsoluteTransforms() {
    json t = json::parse(ReadFileToString(dir_ / "transforms.json"));
    for (auto& f : t["frames"]) f["file_path"] = (dir_ / f["file_path"].get<std::string>()).lexically_normal().string();
    return t;
  }
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

TEST_F(InputsCli, RenderIntoThePhotosFolderIsRefusedBeforeAnyRender) {
  Reconstruct(ws_);
  const auto photos = test::FilesUnder(dir_ / "images");
  const auto r = RunCommand(Perf("render -q " + ws_.string() + " --split all -o " + (dir_ / "images").string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("input"), std::string::npos) << r.output;
  EXPECT_EQ(test::FilesUnder(dir_ / "images"), photos) << "a photo was written over";
}

// import, then each later command alone: the json at WORKSPACE/report.json stays as it was.
TEST_F(InputsCli, AnInputWhereAnOutputGoesIsRefusedByEveryLaterCommand) {
  const fs::path ws = dir_ / "ws2", json_path = ws / "report.json";
  fs::create_directories(ws);
  const std::string original = AbsoluteTransforms().dump();
  std::ofstream(json_path) << original;
  auto r = RunCommand(Perf("import -q --nerf " + json_path.string() + " --workspace " + ws.string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(InputRecordPath(ws)));
  Reconstruct(ws);
  r = RunCommand(Perf("eval -q " + ws.string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("report.json"), std::string::npos) << r.output;
  EXPECT_EQ(ReadFileToString(json_path), original);
  EXPECT_FALSE(fs::exists(WorkspaceLock::PathIn(ws))) << "a refused command left its lock note";
}

// The previous run's files are moved aside and deleted; a user's json among them is neither.
TEST_F(InputsCli, AnInputAmongTheRunFilesIsNeitherMovedNorDeleted) {
  const fs::path ws = dir_ / "ws3", json_path = ws / "recon" / "recon.json";
  fs::create_directories(json_path.parent_path());
  const std::string original = AbsoluteTransforms().dump();
  std::ofstream(json_path) << original;
  auto r = RunCommand(Perf("import -q --nerf " + json_path.string() + " --workspace " + ws.string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunCommand(Perf("reconstruct -q " + ws.string() + " --levels 1 --start-resolution 8 --iterations 1"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("recon.json"), std::string::npos) << r.output;
  EXPECT_EQ(ReadFileToString(json_path), original);
  EXPECT_FALSE(fs::exists(ws / "recon" / "previous"));
}

// A frame that is a FIFO or a link to /dev/zero is refused at once, naming it.
TEST_F(InputsCli, FramesThatAreNotFilesAreRefusedNotRead) {
  json t = AbsoluteTransforms();
  const fs::path fifo = dir_ / "fifo.png", zero = dir_ / "zero.png";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  fs::create_symlink("/dev/zero", zero);
  for (const fs::path& odd : {fifo, zero}) {
    json bad = t;
    bad["frames"][1]["file_path"] = odd.string();
    const fs::path json_path = dir_ / "odd.json";
    std::ofstream(json_path) << bad.dump();
    const auto r = RunCommand(Perf("import -q --nerf " + json_path.string() + " --workspace " + (dir_ / "ws_odd").string()));
    EXPECT_EQ(r.exit_code, 2) << odd << ": " << r.output;
    EXPECT_NE(r.output.find(odd.filename().string()), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("not a regular file"), std::string::npos) << r.output;
  }
  Reconstruct(ws_);
  const auto r = RunCommand(Perf("render -q " + ws_.string() + " --checkpoint " + fifo.string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
}

// A relative json path and an absolute frame path of the same file name are two photos.
TEST_F(InputsCli, ARelativeJsonWithAnAbsoluteFrameOfTheSameNameImports) {
  json t = json::parse(ReadFileToString(dir_ / "transforms.json"));
  // The json beside the photos; one frame's photo copied into another folder, named alike.
  const std::string first = fs::path(t["frames"][0]["file_path"].get<std::string>()).filename().string();
  const std::string second = fs::path(t["frames"][1]["file_path"].get<std::string>()).filename().string();
  fs::create_directories(dir_ / "other");
  fs::copy_file(dir_ / "images" / (second + ".png"), dir_ / "other" / (first + ".png"));
  for (auto& f : t["frames"]) f["file_path"] = "./" + fs::path(f["file_path"].get<std::string>()).filename().string();
  t["frames"][1]["file_path"] = (dir_ / "other" / first).string();
  std::ofstream(dir_ / "images" / "t.json") << t.dump();
  const auto r = RunCommand("cd " + (dir_ / "images").string() + " && " +
                            Perf("import -q --nerf t.json --workspace " + (dir_ / "ws_rel").string()));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("listed twice"), std::string::npos) << r.output;
}

// A file size limit (ulimit -f) ends with exit 3 naming the file, not a silent SIGXFSZ.
TEST_F(InputsCli, AFileSizeLimitIsAnIoErrorNotASignal) {
  const auto r = RunCommand("bash -c \"ulimit -f 0; exec " + Perf("reconstruct -q " + ws_.string() +
                                                                  " --levels 1 --start-resolution 8 --iterations 1") + "\"");
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find(ws_.string()), std::string::npos) << r.output;
}

// Photos that cannot be read are refused by name before COLMAP sees any of them.
TEST(InputsCliPlain, UnreadablePhotosAreNamedBeforeSfm) {
  test::TempDir dir;
  fs::create_directories(dir / "photos");
  for (int i = 0; i < 5; ++i) std::ofstream(dir / "photos" / ("empty" + std::to_string(i) + ".jpg"));
  const auto r = RunCommand(Perf("sfm -q --images " + (dir / "photos").string() + " --workspace " +
                                 (dir / "ws").string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("5 of the 5 photos cannot be read"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("empty0.jpg"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "ws" / "colmap")) << "COLMAP ran";
}

// Ctrl-C stops a stand-alone perf reconstruct at a safe point (exit 130); the checkpoints are
// the last good ones.
TEST_F(InputsCli, CtrlCStopsAStandAloneReconstruct) {
  const int status = test::StopWhenExists(test::PerfBinary() + " reconstruct -q " + ws_.string() +
                                              " --levels 1 --start-resolution 16 --iterations 400",
                                          ws_ / "recon" / "log.jsonl", SIGINT, 500);
  ASSERT_TRUE(WIFEXITED(status)) << "Ctrl-C should stop perf reconstruct at a safe point, not kill it";
  EXPECT_EQ(WEXITSTATUS(status), 130);
  EXPECT_FALSE(fs::exists(ws_ / "recon" / "level_0.perfvol")) << "stopped too late to test anything";
}

}  // namespace
}  // namespace perf
