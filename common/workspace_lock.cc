#include "common/workspace_lock.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <string>

#include "common/errors.h"
#include "common/owned_files.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

// Who holds the lock, from its note (.perf/lock).
std::string Holder(const fs::path& info) {
  std::array<char, 256> buf{};
  const UniqueFd fd(::open(info.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOFOLLOW));
  const ssize_t n = fd.valid() ? ::pread(fd.get(), buf.data(), buf.size() - 1, 0) : 0;
  std::string s = n > 0 ? std::string(buf.data(), static_cast<size_t>(n)) : std::string();
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s.empty() ? "another perf process" : s;
}

}  // namespace

fs::path WorkspaceLock::PathIn(const fs::path& workspace) { return PrivateFolder(workspace) / "lock"; }

WorkspaceLock::WorkspaceLock(const fs::path& workspace, std::string_view command) {
  std::error_code ec;
  created_ = !fs::exists(workspace, ec);
  fs::create_directories(workspace, ec);
  if (ec || !fs::is_directory(workspace)) {
    throw IoError(workspace.string(), "cannot create the workspace folder: " + (ec ? ec.message() : "not a folder"),
                  "choose a writable location");
  }
  // The lock is on the folder itself, which no other command deletes while it is in use;
  // .perf.lock only says who holds it (deleting it lets nobody in).
  fd_ = UniqueFd(::open(workspace.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (!fd_.valid()) {
    throw IoError(workspace.string(), StrCat("cannot open the workspace folder: ", std::strerror(errno)),
                  "check that the workspace folder is readable");
  }
  info_ = PathIn(workspace);
  if (::flock(fd_.get(), LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    if (err == EWOULDBLOCK) {
      throw InputError(info_.string(), "lock", Holder(info_), "another perf command is writing this workspace",
                       "wait for it to finish (or stop it), or use another workspace folder");
    }
    throw IoError(workspace.string(), StrCat("cannot lock the workspace: ", std::strerror(err)),
                  "use a workspace on a local file system");
  }
  // Who holds it, for the message a second writer gets, in PERF's own folder (made here, and
  // removed again if it is left empty). Best effort: the lock is what counts.
  struct stat st {};
  created_private_ = ::mkdir(info_.parent_path().c_str(), 0755) == 0;
  if (::lstat(info_.parent_path().c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) return;
  const UniqueFd info(::open(info_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_NOFOLLOW, 0644));
  if (info.valid()) {
    const std::string who = StrCat("pid ", ::getpid(), " (perf ", command, ")\n");
    [[maybe_unused]] const ssize_t n = ::write(info.get(), who.data(), who.size());
  }
}

WorkspaceLock::~WorkspaceLock() {
  // Nothing of the lock stays behind: the holder's note goes before the lock is released.
  std::error_code ec;
  if (!info_.empty()) fs::remove(info_, ec);
  if (created_private_) ::rmdir(info_.parent_path().c_str());  // only if empty
}

}  // namespace perf
