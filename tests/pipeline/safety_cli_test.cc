// DESIGN.md "Safety" as a user meets it on the command line: a full disk (RLIMIT_FSIZE = 0 in
// the child) fails with exit 3 naming the final file and leaves the previous good outputs and
// checkpoints in place; a failed reconstruction keeps the last good one; one writer per
// workspace; out-of-range options are exit 2 naming the option; temporaries of killed runs are
// swept; a failed import into a new folder leaves nothing.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <fstream>
#include <map>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/owned_files.h"
#include "common/workspace_lock.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

std::string Perf(const std::string& args) { return test::PerfBinary() + " " + args; }

// `perf args` with files limited to 0 bytes, as on a full disk (SIGXFSZ ignored, so writes
// fail with EFBIG instead of killing the process).
std::string PerfOnFullDisk(const std::string& args) {
  return "bash -c \"ulimit -f 0; trap '' XFSZ; exec " + Perf(args) + "\"";
}

std::map<fs::path, std::string> Snapshot(const fs::path& dir) {
  std::map<fs::path, std::string> files;
  if (!fs::exists(dir)) return files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    // Outputs only: PERF's own bookkeeping (.perf/: its record of what it wrote, the lock's note)
    // is rewritten by any command that takes the lock.
    const fs::path rel = e.path().lexically_relative(dir);
    if (e.is_regular_file() && *rel.begin() != ".perf") files[e.path()] = ReadFileToString(e.path());
  }
  return files;
}

bool HasTemporaries(const fs::path& dir) {
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.path().filename().string().find(".tmp") != std::string::npos) return true;
  }
  return false;
}

class SafetyCli : public ::testing::Test {
 protected:
  void SetUp() override { test::MakeSyntheticWorkspace(dir_.path(), ws_); }
  void Reconstruct() {
    const auto r = RunCommand(Perf("reconstruct -q " + ws_.string() + kRecon));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static constexpr const char* kRecon = " --levels 1 --start-resolution 16 --iterations 3";
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

TEST_F(SafetyCli, FullDiskKeepsThePreviousExportAndNamesTheFile) {
  Reconstruct();
  auto r = RunCommand(Perf("export -q " + ws_.string() + " --orbit-frames 2"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto before = Snapshot(ws_);
  for (const std::string only_masks : {" --no-mesh --no-volume --no-renders", ""}) {
    r = RunCommand(PerfOnFullDisk("export -q " + ws_.string() + " --orbit-frames 2" + only_masks));
    EXPECT_EQ(r.exit_code, 3) << r.output;
    EXPECT_NE(r.output.find(ws_.string()), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find(".tmp"), std::string::npos) << r.output;  // the final name, not the temporary's
    EXPECT_EQ(Snapshot(ws_), before) << "an output changed" << only_masks;
    EXPECT_FALSE(HasTemporaries(ws_));
  }
}

TEST_F(SafetyCli, FailedReconstructionKeepsTheLastGoodCheckpoint) {
  Reconstruct();
  const auto before = Snapshot(ws_ / "recon");
  ASSERT_EQ(before.count(ws_ / "recon" / "level_0.perfvol"), 1u);
  // A full disk after the run has started, and a level that cannot fit in memory.
  auto r = RunCommand(PerfOnFullDisk("reconstruct -q " + ws_.string() + kRecon));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_EQ(Snapshot(ws_ / "recon"), before);
  r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 1024"));
  EXPECT_EQ(r.exit_code, 5) << r.output;
  EXPECT_NE(r.output.find("--start-resolution"), std::string::npos) << r.output;
  EXPECT_EQ(Snapshot(ws_ / "recon"), before);

  // A run killed after moving the old checkpoints aside: the next reconstruct puts them back.
  test::StopWhenExists(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 64 --iterations 400"),
                       ws_ / "recon" / "previous" / "level_0.perfvol", SIGKILL, 100);
  ASSERT_TRUE(fs::exists(ws_ / "recon" / "previous" / "level_0.perfvol"));
  r = RunCommand(Perf("reconstruct " + ws_.string() + kRecon + " --resume"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("nothing to resume"), std::string::npos) << r.output;
  EXPECT_EQ(Snapshot(ws_ / "recon"), before);
}

TEST_F(SafetyCli, OneWriterPerWorkspace) {
  {
    WorkspaceLock held(ws_, "run");
    for (const std::string& cmd : {"reconstruct -q " + ws_.string() + kRecon, "export -q " + ws_.string(),
                                   "eval -q " + ws_.string(), "render -q " + ws_.string()}) {
      const auto r = RunCommand(Perf(cmd));
      EXPECT_EQ(r.exit_code, 2) << cmd << "\n" << r.output;
      EXPECT_NE(r.output.find(StrCat("pid ", ::getpid(), " (perf run)")), std::string::npos) << r.output;
    }
    const auto r = RunCommand(Perf("import -q --nerf " + (dir_ / "transforms.json").string() + " -w " + ws_.string()));
    EXPECT_EQ(r.exit_code, 2) << r.output;
    EXPECT_FALSE(fs::exists(ws_ / "recon"));
  }
  Reconstruct();  // released
}

TEST_F(SafetyCli, OutOfRangeOptionsAreRefusedByName) {
  const std::string ws = ws_.string();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"render " + ws + " -j 100000", "-j"},
      {"export " + ws + " -j -3", "-j"},
      {"export " + ws + " --iso nan", "--iso"},
      {"export " + ws + " --iso -1", "--iso"},
      {"export " + ws + " --iso 1", "--iso"},
      {"export " + ws + " --min-component nan", "--min-component"},
      {"export " + ws + " --vdb-min-opacity -1", "--vdb-min-opacity"},
      {"export " + ws + " --orbit-frames 100000", "--orbit-frames"},
      {"reconstruct " + ws + " --diagonal-floor nan", "--diagonal-floor"},
      {"reconstruct " + ws + " --diagonal-floor inf", "--diagonal-floor"},
      {"import --nerf " + (dir_ / "transforms.json").string() + " -w " + (dir_ / "ws2").string() + " --shells 1000",
       "--shells"},
      {"import --nerf " + (dir_ / "transforms.json").string() + " -w " + (dir_ / "ws2").string() +
           " --box-size 1e300 1e300 1e300",
       "--box-size"},
  };
  const auto before = Snapshot(ws_);
  for (const auto& [args, option] : cases) {
    const auto r = RunCommand(Perf(args));
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    EXPECT_NE(r.output.find(option), std::string::npos) << args << "\n" << r.output;
  }
  EXPECT_EQ(Snapshot(ws_), before);
  EXPECT_FALSE(fs::exists(dir_ / "ws2"));  // a failed import into a new folder leaves nothing
}

// What a killed run left half written goes with the next command; a user's file named like a
// temporary, in a folder PERF writes, stays (it is no temporary of PERF's: the record says so).
TEST_F(SafetyCli, TemporariesOfKilledRunsAreSwept) {
  Reconstruct();
  fs::create_directories(ws_ / "masks" / "soft");
  const fs::path users = ws_ / "masks" / "soft" / "view0.tmp999999999-4.png";  // no such pid
  std::ofstream(users) << "a user's file";
  const pid_t child = ::fork();
  if (child == 0) {  // a perf killed while writing a mask
    UseOwnershipRecord(ws_);
    WriteAtomically(ws_ / "masks" / "soft" / "view1.png", [](const fs::path&) { ::_exit(0); });
    ::_exit(1);
  }
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  const auto stale = [&] {
    int n = 0;
    for (const auto& e : fs::directory_iterator(ws_ / "masks" / "soft")) n += e.path().filename().string().rfind("view1.tmp", 0) == 0;
    return n;
  };
  ASSERT_EQ(stale(), 1);
  const auto r = RunCommand(Perf("export -q " + ws_.string() + " --no-mesh --no-volume --no-renders --no-foreground"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(stale(), 0);
  EXPECT_EQ(ReadFileToString(users), "a user's file");
}

}  // namespace
}  // namespace perf
