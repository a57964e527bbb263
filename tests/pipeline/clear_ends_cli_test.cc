// Clear ends: a --nerf that is a FIFO or a device and a FIFO cameras.bin are named as what they
// are; after a killed reconstruct the later commands find the run before it; perf run --view lets
// other commands in once the run is done; a first command that fails leaves no folder.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "common/atomic_file.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

std::string Perf(const std::string& args) { return "timeout 120 " + test::PerfBinary() + " " + args; }

class ClearEndsCli : public ::testing::Test {
 protected:
  void SetUp() override { test::MakeSyntheticWorkspace(dir_.path(), ws_); }
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

TEST_F(ClearEndsCli, ANerfJsonThatIsNotAFileIsNamedAsSuch) {
  const fs::path fifo = dir_ / "fifo.json";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  for (const fs::path& odd : {fifo, fs::path("/dev/zero")}) {
    for (const std::string command : {"import -q --nerf ", "run --log-level quiet --nerf "}) {
      const fs::path ws = dir_ / "ws_odd";
      const auto r = RunCommand(Perf(command + odd.string() + " --workspace " + ws.string()));
      EXPECT_EQ(r.exit_code, 2) << command << odd << ": " << r.output;
      EXPECT_NE(r.output.find(odd.string()), std::string::npos) << r.output;
      EXPECT_NE(r.output.find("not a regular file"), std::string::npos) << r.output;
      EXPECT_FALSE(fs::exists(ws)) << command << ": a refused first command left its folder";
    }
  }
}

TEST_F(ClearEndsCli, AFifoCamerasBinIsNamedAsSuch) {
  const fs::path model = dir_ / "model";
  fs::create_directories(model);
  ASSERT_EQ(::mkfifo((model / "cameras.bin").c_str(), 0644), 0);
  std::ofstream(model / "images.bin");
  std::ofstream(model / "points3D.bin");
  const auto r = RunCommand(Perf("import -q --colmap " + model.string() + " --images " + (dir_ / "images").string() +
                                 " --workspace " + (dir_ / "ws_fifo").string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("cameras.bin"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("not a regular file"), std::string::npos) << r.output;
}

// A fresh reconstruct moves the run before it aside and is killed before its first level: export,
// eval and render find that run again (it was in recon/previous/).
TEST_F(ClearEndsCli, AfterAKilledReconstructTheRunBeforeItIsFound) {
  auto r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 8 --iterations 1"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string checkpoint = ReadFileToString(ws_ / "recon" / "level_0.perfvol");
  test::StopWhenExists(test::PerfBinary() + " reconstruct -q " + ws_.string() +
                           " --levels 1 --start-resolution 64 --iterations 400",
                       ws_ / "recon" / "previous" / "level_0.perfvol", SIGKILL, 100);
  ASSERT_FALSE(fs::exists(ws_ / "recon" / "level_0.perfvol")) << "killed too late to test anything";
  for (const std::string command : {"render -q ", "eval -q ", "export -q --no-mesh --orbit-frames 0 "}) {
    r = RunCommand(Perf(command + ws_.string()));
    EXPECT_EQ(r.exit_code, 0) << command << r.output;
  }
  EXPECT_EQ(ReadFileToString(ws_ / "recon" / "level_0.perfvol"), checkpoint);
  EXPECT_FALSE(fs::exists(ws_ / "recon" / "previous"));
}

// Once perf run --view has finished, its page stays but the workspace is free for other commands.
TEST_F(ClearEndsCli, RunWithViewReleasesTheWorkspaceWhenDone) {
  const fs::path out = dir_ / "run.out";
  const pid_t pid = ::fork();
  if (pid == 0) {
    const std::string command = test::PerfBinary() + " run --nerf " + (dir_ / "transforms.json").string() +
                                " --workspace " + (dir_ / "ws_view").string() +
                                " --levels 1 --iterations 1 --preset preview --view --view-port 0 > " + out.string() + " 2>&1";
    ::execl("/bin/sh", "sh", "-c", ("exec " + command).c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(3);
  bool done = false;
  while (!done && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    std::ifstream in(out);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    done = text.find("the page stays") != std::string::npos;
  }
  ASSERT_TRUE(done) << "perf run --view did not finish";
  const auto r = RunCommand(Perf("eval -q " + (dir_ / "ws_view").string()));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  ::kill(pid, SIGINT);
  int status = 0;
  ::waitpid(pid, &status, 0);
}

// perf sfm refused before COLMAP runs leaves no workspace it made.
TEST_F(ClearEndsCli, ARefusedFirstSfmLeavesNoFolder) {
  fs::create_directories(dir_ / "empty_photos");
  std::ofstream(dir_ / "empty_photos" / "a.jpg");
  const fs::path ws = dir_ / "ws_sfm";
  const auto r = RunCommand(Perf("sfm -q --images " + (dir_ / "empty_photos").string() + " --workspace " + ws.string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_FALSE(fs::exists(ws));
}

}  // namespace
}  // namespace perf
