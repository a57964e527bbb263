// The write layer every output goes through (common/atomic_file.h, common/workspace_lock.h): a
// failed write (a full disk, simulated with RLIMIT_FSIZE in a child process) leaves the old file
// and no temporary, and its error names the final path; inputs cannot be replaced whatever path
// names them; one writer per workspace. (What PERF may replace: owned_files_test.cc.)
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <fstream>
#include <string>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/workspace_lock.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;

int CountTemporaries(const fs::path& dir) {
  int n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir)) n += e.path().filename().string().find(".tmp") != std::string::npos;
  return n;
}

// Runs `body` in a child process whose files may not grow beyond `max_bytes` (writes beyond it
// fail with EFBIG, as on a full disk); returns the child's exit code.
int InChildWithFileLimit(rlim_t max_bytes, const std::function<int()>& body) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    std::signal(SIGXFSZ, SIG_IGN);
    const rlimit limit{max_bytes, max_bytes};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    int code = 99;
    try {
      code = body();
    } catch (...) {
      code = 98;
    }
    ::_exit(code);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(SafeWrite, FullDiskKeepsTheOldFileAndNamesTheTarget) {
  test::TempDir dir;
  const fs::path target = dir / "volume.vdb";
  WriteFileAtomically(target, "the good old file");
  const std::string big(1 << 16, 'x');
  for (const bool stream : {false, true}) {
    const int code = InChildWithFileLimit(4096, [&] {
      try {
        if (stream) {
          WriteStreamAtomically(target, [&](std::ostream& out) { out << big; });
        } else {
          WriteFileAtomically(target, big, Durability::kDurable);
        }
      } catch (const IoError& e) {
        const std::string msg = e.what();
        // The final path, not the temporary's name.
        return e.path() == target.string() && msg.find(".tmp") == std::string::npos ? 0 : 2;
      }
      return 1;  // the failure went unnoticed
    });
    EXPECT_EQ(code, 0) << (stream ? "stream" : "bytes");
    EXPECT_EQ(ReadFileToString(target), "the good old file");
    EXPECT_EQ(CountTemporaries(dir.path()), 0);
  }
}

TEST(SafeWrite, FailedWriterLeavesNothing) {
  test::TempDir dir;
  EXPECT_THROW(WriteStreamAtomically(dir / "a.json", [](std::ostream&) { throw IoError("x", "boom"); }), IoError);
  EXPECT_THROW(WriteAtomically(dir / "b.png", [](const fs::path& tmp) {
                 std::ofstream(tmp) << "half";
                 throw IoError("x", "boom");
               }),
               IoError);
  EXPECT_TRUE(fs::is_empty(dir.path()));
}

TEST(SafeWrite, InputsAreNeverReplacedWhateverTheirName) {
  test::TempDir dir;
  fs::create_directories(dir / "photos");
  const fs::path photo = dir / "photos" / "a.png";
  std::ofstream(photo) << "original";
  fs::create_hard_link(photo, dir / "hard.png");
  fs::create_directory_symlink(dir / "photos", dir / "ws");
  ProtectInput(photo);
  for (const fs::path& alias : {photo, dir / "hard.png", dir / "ws" / "a.png", dir / "photos" / ".." / "photos" / "a.png"}) {
    EXPECT_THROW(WriteFileAtomically(alias, "overwritten"), InputError) << alias;
    EXPECT_THROW(CheckNotInput(alias), InputError) << alias;
  }
  EXPECT_EQ(ReadFileToString(photo), "original");
  WriteFileAtomically(dir / "photos" / "b.png", "a new file is fine");
  EXPECT_NO_THROW(CheckNotInput(dir / "missing.png"));
}

TEST(WorkspaceLock, OneWriterAtATime) {
  test::TempDir dir;
  const fs::path ws = dir / "ws";
  {
    WorkspaceLock first(ws, "run");
    EXPECT_TRUE(first.created_workspace());
    try {
      WorkspaceLock second(ws, "export");
      ADD_FAILURE() << "a second writer got the lock";
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(StrCat("pid ", ::getpid())), std::string::npos) << msg;
      EXPECT_NE(msg.find("perf run"), std::string::npos) << msg;
    }
  }
  WorkspaceLock again(ws, "export");  // released with the first
  EXPECT_FALSE(again.created_workspace());
}

// The lock is on the folder: deleting its note (.perf/lock) lets no second writer in, and the note goes
// with the lock (a refused command leaves nothing in the folder it was given).
TEST(WorkspaceLock, HoldsWithoutItsNoteAndLeavesNothing) {
  test::TempDir dir;
  const fs::path ws = dir / "ws";
  {
    WorkspaceLock first(ws, "run");
    ASSERT_TRUE(fs::exists(WorkspaceLock::PathIn(ws)));
    fs::remove(WorkspaceLock::PathIn(ws));
    EXPECT_THROW(WorkspaceLock(ws, "export"), InputError);
  }
  EXPECT_FALSE(fs::exists(WorkspaceLock::PathIn(ws)));
  EXPECT_TRUE(fs::is_empty(ws));
}

// Inputs stay protected in later processes: the workspace's record registers them again.
TEST(InputRecord, ProtectsTheRecordedInputsInALaterCommand) {
  test::TempDir dir;
  const fs::path photo = dir / "photos" / "a.png", ws = dir / "ws";
  fs::create_directories(photo.parent_path());
  fs::create_directories(ws);
  std::ofstream(photo) << "original";
  ProtectInput(photo);
  WriteInputRecord(ws);
  const std::string record = ReadFileToString(InputRecordPath(ws));
  EXPECT_NE(record.find(fs::absolute(photo).string()), std::string::npos) << record;
  EXPECT_GE(ProtectRecordedInputs(ws), 1);
  EXPECT_EQ(ProtectRecordedInputs(dir / "no_workspace"), 0);
  std::ofstream(InputRecordPath(ws)) << "{ not json";
  EXPECT_THROW(ProtectRecordedInputs(ws), InputError);
}

// A FIFO or a device is refused, not read forever (ReadFileToString).
TEST(SafeRead, OnlyRegularFilesAreRead) {
  test::TempDir dir;
  const fs::path fifo = dir / "frame.png";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  EXPECT_THROW(ReadFileToString(fifo), InputError);
  EXPECT_THROW(ReadFileToString("/dev/zero"), InputError);
  EXPECT_THROW(ReadFileToString(dir.path()), InputError);
  std::ofstream(dir / "a.txt") << "abc";
  EXPECT_EQ(ReadFileToString(dir / "a.txt"), "abc");
}

}  // namespace
}  // namespace perf
