// PERF changes only what it made (common/owned_files.h): a file PERF wrote may be replaced, a
// user's file, a link, or a PERF file changed since may not; logs never follow a link; the sweep
// removes only the journalled temporaries of dead processes, never a user's file named like one;
// the record outlives the process that wrote it.
#include "common/owned_files.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>

#include "common/atomic_file.h"
#include "common/log_file.h"
#include "common/errors.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;

class OwnedFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    fs::create_directories(ws_);
    UseOwnershipRecord(ws_);
  }
  void TearDown() override { DropOwnershipRecord(); }
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

TEST_F(OwnedFiles, OnlyWhatPerfWroteIsReplaced) {
  const fs::path ours = ws_ / "report.json", users = ws_ / "notes.json", link = ws_ / "link.json";
  WriteFileAtomically(ours, "1");
  EXPECT_TRUE(IsOwned(ours));
  EXPECT_NO_THROW(WriteFileAtomically(ours, "2"));  // PERF's own, again
  std::ofstream(users) << "a user's";
  EXPECT_FALSE(IsOwned(users));
  EXPECT_THROW(WriteFileAtomically(users, "x"), InputError);
  EXPECT_EQ(ReadFileToString(users), "a user's");
  fs::create_symlink(ours, link);
  EXPECT_THROW(WriteFileAtomically(link, "x"), InputError);
  // A PERF file the user changed since (same inode, new size) is the user's now.
  std::ofstream(ours, std::ios::app) << " edited";
  EXPECT_FALSE(IsOwned(ours));
  try {
    CheckReplaceable(ours, "the report");
    ADD_FAILURE() << "a changed file was replaceable";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(ours.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("choose another path"), std::string::npos) << msg;
  }
  EXPECT_NO_THROW(CheckReplaceable(ws_ / "absent.json"));
  EXPECT_FALSE(fs::exists(ws_ / "absent.json"));
}

TEST_F(OwnedFiles, TheRecordOutlivesTheProcess) {
  const fs::path ours = ws_ / "masks" / "a.png";
  EnsureWritableDirectory(ours.parent_path());
  WriteFileAtomically(ours, "png");
  DropOwnershipRecord();
  UseOwnershipRecord(ws_);  // a later command
  EXPECT_TRUE(IsOwned(ours));
  EXPECT_TRUE(IsOwned(ours.parent_path()));
  // A workspace with no record at all owns nothing.
  const fs::path other = dir_ / "other";
  fs::create_directories(other);
  std::ofstream(other / "scene.json") << "{}";
  DropOwnershipRecord();
  UseOwnershipRecord(other);
  EXPECT_FALSE(IsOwned(other / "scene.json"));
  EXPECT_THROW(WriteFileAtomically(other / "scene.json", "{}"), InputError);
}

// A copy of the workspace (cp -a keeps sizes and times, not inodes) is still PERF's to replace:
// its finished files, and a log PERF had closed.
TEST_F(OwnedFiles, ACopyOfTheWorkspaceStaysPerfs) {
  WriteFileAtomically(ws_ / "export.json", "{}");
  { LogFile log(ws_ / "log.jsonl", true, "log"); log.Write("a\n"); }
  DropOwnershipRecord();
  const fs::path copy = dir_ / "copy";
  ASSERT_EQ(std::system(("cp -a " + ws_.string() + "/. " + copy.string()).c_str()), 0);
  UseOwnershipRecord(copy);
  EXPECT_TRUE(IsOwned(copy / "export.json"));
  EXPECT_TRUE(IsOwned(copy / "log.jsonl"));
  std::ofstream(copy / "export.json", std::ios::app) << " ";  // edited in the copy: not PERF's any more
  EXPECT_FALSE(IsOwned(copy / "export.json"));
}

TEST_F(OwnedFiles, LogsNeverFollowALinkNorAppendToAUsersFile) {
  const fs::path log = ws_ / "log.jsonl", victim = dir_ / "victim.txt", users = ws_ / "users.jsonl";
  {
    UniqueFd fd = OpenLog(log, true, "log");
    ASSERT_TRUE(fd.valid());
    ASSERT_EQ(::write(fd.get(), "a\n", 2), 2);
  }
  UniqueFd again = OpenLog(log, true, "log");  // PERF's own, appended
  ASSERT_EQ(::write(again.get(), "b\n", 2), 2);
  EXPECT_EQ(ReadFileToString(log), "a\nb\n");
  std::ofstream(victim) << "v";
  fs::remove(log);
  fs::create_symlink(victim, log);
  EXPECT_THROW(OpenLog(log, true, "log"), InputError);
  std::ofstream(users) << "u";
  EXPECT_THROW(OpenLog(users, true, "log"), InputError);
  EXPECT_EQ(ReadFileToString(victim), "v");
  EXPECT_EQ(ReadFileToString(users), "u");
}

TEST_F(OwnedFiles, RemovingATreeLeavesWhatIsNotOurs) {
  const fs::path dir = ws_ / "recon" / "previous";
  EnsureWritableDirectory(dir);
  WriteFileAtomically(dir / "level_0.perfvol", "ours");
  std::ofstream(dir / "mine.txt") << "a user's";
  EXPECT_FALSE(RemoveOwnedTree(ws_ / "recon"));
  EXPECT_FALSE(fs::exists(dir / "level_0.perfvol"));
  EXPECT_TRUE(fs::exists(dir / "mine.txt"));
  EXPECT_THROW(RemoveOwned(dir / "mine.txt"), InputError);
  fs::remove(dir / "mine.txt");
  EXPECT_TRUE(RemoveOwnedTree(ws_ / "recon"));
}

// A killed process's temporaries go; a user's file named like a temporary, in a folder PERF
// writes, and a living process's temporary stay.
TEST_F(OwnedFiles, TheSweepRemovesOnlyJournalledTemporariesOfDeadProcesses) {
  const fs::path images = ws_ / "images";
  EnsureWritableDirectory(images);
  const fs::path user = images / "holiday.tmp999999-7.JPG";
  std::ofstream(user) << "a photo";
  const pid_t child = ::fork();
  if (child == 0) {
    DropOwnershipRecord();
    UseOwnershipRecord(ws_);
    // Killed while writing: the temporary stays behind.
    WriteAtomically(images / "a.png", [](const fs::path&) { ::_exit(0); });
    ::_exit(1);
  }
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  int left = 0;
  for (const auto& e : fs::directory_iterator(images)) left += e.path().filename().string().rfind("a.tmp", 0) == 0;
  ASSERT_EQ(left, 1);
  DropOwnershipRecord();
  UseOwnershipRecord(ws_);
  EXPECT_EQ(SweepOwnedTemporaries(), 1);
  left = 0;
  for (const auto& e : fs::directory_iterator(images)) left += e.path().filename().string().rfind("a.tmp", 0) == 0;
  EXPECT_EQ(left, 0);
  EXPECT_TRUE(fs::exists(user));
  EXPECT_EQ(SweepOwnedTemporaries(), 0);
}

TEST(OwnedFilesPlain, WithoutARecordOnlyInputsAreChecked) {
  DropOwnershipRecord();
  test::TempDir dir;
  std::ofstream(dir / "a.txt") << "x";
  EXPECT_NO_THROW(WriteFileAtomically(dir / "a.txt", "y"));
  EXPECT_EQ(ReadFileToString(dir / "a.txt"), "y");
}

TEST(OwnedFilesPlain, APrivateFolderThatIsNotAFolderIsRefused) {
  test::TempDir dir;
  std::ofstream(PrivateFolder(dir.path())) << "x";
  EXPECT_THROW(UseOwnershipRecord(dir.path()), InputError);
  fs::remove(PrivateFolder(dir.path()));
  fs::create_directories(dir / "elsewhere");
  fs::create_directory_symlink(dir / "elsewhere", PrivateFolder(dir.path()));
  EXPECT_THROW(UseOwnershipRecord(dir.path()), InputError);
  DropOwnershipRecord();
}

}  // namespace
}  // namespace perf
