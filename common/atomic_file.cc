#include "common/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <vector>

#include "common/errors.h"
#include "common/owned_files.h"
#include "common/unique_fd.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

constexpr const char* kDiskHint = "check the free disk space and that the folder is writable";

std::string Errno() { return std::strerror(errno); }

void WriteAll(int fd, std::string_view data, const fs::path& target) {
  while (!data.empty()) {
    const ssize_t n = ::write(fd, data.data(), data.size());
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw IoError(target.string(), "writing failed: " + (n < 0 ? Errno() : std::string("no progress")), kDiskHint);
    data.remove_prefix(static_cast<size_t>(n));
  }
}

// fsync of a folder, so that a rename in it survives a power cut. Best effort: some file
// systems refuse to fsync folders.
void SyncDirectory(const fs::path& dir) {
  const UniqueFd fd(::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (fd.valid()) ::fsync(fd.get());
}

// For tests: PERF_TEST_FAIL_WRITE names a file (its name, e.g. mesh.obj) whose every write fails
// as on a full disk, so that a failure part way through a stage can be reproduced.
void FailIfTestSaysSo(const fs::path& target) {
  static const char* const name = std::getenv("PERF_TEST_FAIL_WRITE");
  if (name != nullptr && *name != 0 && target.filename() == name) {
    throw IoError(target.string(), "writing failed: injected (PERF_TEST_FAIL_WRITE)", kDiskHint);
  }
}

// Moves the finished temporary into place unless the target is an input or a file PERF did not
// write (the one place every writer checks that), journalling it first, then syncs the folder.
void Commit(const fs::path& tmp, const fs::path& target, Durability durability) {
  FailIfTestSaysSo(target);
  CheckMayReplace(target);
  RecordOutput(target, tmp);
  std::error_code ec;
  fs::rename(tmp, target, ec);
  if (ec) {
    throw IoError(target.string(), "cannot move the finished file into place: " + ec.message(),
                  "check that the folder is writable and on one file system");
  }
  if (durability == Durability::kDurable) SyncDirectory(target.parent_path());
}

// Runs `body`; on any exception removes `tmp` and rethrows.
template <typename Body>
void RemovingOnFailure(const fs::path& tmp, Body&& body) {
  try {
    body();
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
}

// Makes the temporary for `target` (O_EXCL: never a file that was there) and journals it, so
// that a sweep after a kill may remove it (owned_files.h). Checks first that the target may be
// replaced, so that no work is done for an output that would be refused.
UniqueFd CreateTemporary(const fs::path& target, fs::path* tmp) {
  CheckMayReplace(target);
  *tmp = TempPathFor(target);
  UniqueFd fd(::open(tmp->c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOFOLLOW, 0644));
  if (fd.get() < 0) throw IoError(target.string(), "cannot create the file: " + Errno(), kDiskHint);
  RemovingOnFailure(*tmp, [&] { RecordTemporary(*tmp); });
  return fd;
}

}  // namespace

void CheckMayReplace(const fs::path& target, std::string_view what) {
  CheckNotInput(target, what);
  CheckReplaceable(target, what);
}

fs::path TempPathFor(const fs::path& target) {
  static std::atomic<unsigned> counter{0};
  const std::string suffix =
      StrCat(".tmp", ::getpid(), "-", counter.fetch_add(1), target.extension().string());
  return target.parent_path() / (target.stem().string() + suffix);
}

void WriteFileAtomically(const fs::path& target, std::string_view contents, Durability durability) {
  fs::path tmp;
  UniqueFd fd = CreateTemporary(target, &tmp);
  RemovingOnFailure(tmp, [&] {
    WriteAll(fd.get(), contents, target);
    if (durability == Durability::kDurable && ::fsync(fd.get()) != 0) {
      throw IoError(target.string(), "writing failed (fsync): " + Errno(), kDiskHint);
    }
    if (!fd.Close()) throw IoError(target.string(), "writing failed (close): " + Errno(), kDiskHint);
    Commit(tmp, target, durability);
  });
}

void WriteStreamAtomically(const fs::path& target, const std::function<void(std::ostream&)>& write,
                           Durability durability) {
  std::ostringstream buffer(std::ios::binary);
  write(buffer);
  if (!buffer) throw IoError(target.string(), "the data could not be formatted in memory");
  WriteFileAtomically(target, std::move(buffer).str(), durability);
}

void WriteAtomically(const fs::path& target, const std::function<void(const fs::path&)>& write,
                     Durability durability) {
  fs::path tmp;
  CreateTemporary(target, &tmp).Close();  // the library writes over the journalled empty file
  RemovingOnFailure(tmp, [&] {
    write(tmp);
    // What the library left must be a file whose data reached the file system.
    UniqueFd fd(::open(tmp.c_str(), O_RDONLY | O_CLOEXEC));
    if (fd.get() < 0) throw IoError(target.string(), "the written file is gone: " + Errno(), kDiskHint);
    if (durability == Durability::kDurable && ::fsync(fd.get()) != 0) {
      throw IoError(target.string(), "writing failed (fsync): " + Errno(), kDiskHint);
    }
    fd.Close();
    Commit(tmp, target, durability);
  });
}

void EnsureWritableDirectory(const fs::path& dir) {
  CheckNoLinkOnTheWay(dir / "_");  // no folder made outside the workspace through a link in it
  std::error_code ec;
  // Made one level at a time, each journalled (owned_files.h): PERF may remove it again once empty.
  std::vector<fs::path> missing;
  for (fs::path p = dir; !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
    missing.push_back(p);
    if (p == p.parent_path()) break;
  }
  for (auto it = missing.rbegin(); it != missing.rend() && !ec; ++it) {
    if (fs::create_directory(*it, ec)) RecordFolder(*it);
  }
  if (ec || !fs::is_directory(dir)) {
    throw IoError(dir.string(), "cannot create the folder: " + (ec ? ec.message() : "not a folder"),
                  "choose a writable location");
  }
  if (::access(dir.c_str(), W_OK | X_OK) != 0) {
    throw IoError(dir.string(), "the folder is not writable", "choose a writable location or fix its permissions");
  }
}

void EnsureWorkFolder(const fs::path& dir) {
  std::error_code ec;
  if (fs::exists(dir, ec) || fs::is_symlink(dir, ec)) {
    CheckReplaceable(dir, "using it as PERF's working folder");
    EnsureWritableDirectory(dir);
    return;
  }
  EnsureWritableDirectory(dir.parent_path().empty() ? fs::path(".") : dir.parent_path());
  if (!fs::create_directory(dir, ec) || ec) {
    throw IoError(dir.string(), "cannot create the folder: " + (ec ? ec.message() : "it appeared meanwhile"),
                  "choose a writable location");
  }
  RecordWorkFolder(dir);
}

// Throws InputError naming `path` unless `st` (its status) is a regular file's.
static void RequireRegular(const fs::path& path, const struct stat& st) {
  if (!S_ISREG(st.st_mode)) {
    throw InputError(path.string(), "", "", "not a regular file (a device, FIFO or folder)",
                     "pass the path of the file itself");
  }
}

void CheckRegularFile(const fs::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw IoError(path.string(), StrCat("cannot open for reading: ", Errno()));
  RequireRegular(path, st);
}

std::string ReadFileToString(const fs::path& path) {
  // Opened without blocking (a FIFO would wait for a writer) and read only if it is a regular
  // file, at most its size at open (a device such as /dev/zero never ends).
  UniqueFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK));
  if (!fd.valid()) throw IoError(path.string(), StrCat("cannot open for reading: ", Errno()));
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0) throw IoError(path.string(), "cannot read its size: " + Errno());
  RequireRegular(path, st);
  std::string data(static_cast<size_t>(st.st_size), '\0');
  size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::read(fd.get(), data.data() + done, data.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw IoError(path.string(), "reading failed: " + Errno());
    if (n == 0) break;  // shrank while being read
    done += static_cast<size_t>(n);
  }
  data.resize(done);
  return data;
}

}  // namespace perf
