#include "common/workspace_lock.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <regex>
#include <string>

#include "common/errors.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

// The pid in a temporary's name (atomic_file.h's TempPathFor), or 0 if it is not one.
pid_t TemporaryOwner(const std::string& name) {
  static const std::regex kTemp(R"(\.tmp([0-9]{1,9})-[0-9]+)");
  std::smatch m;
  if (!std::regex_search(name, m, kTemp)) return 0;
  return static_cast<pid_t>(std::stol(m[1].str()));
}

bool ProcessGone(pid_t pid) { return pid != ::getpid() && ::kill(pid, 0) != 0 && errno == ESRCH; }

int SweepFolder(const fs::path& dir, bool recursive) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec) || fs::is_symlink(dir, ec)) return 0;
  int removed = 0;
  for (fs::directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec), end; !ec && it != end;
       it.increment(ec)) {
    const fs::path p = it->path();
    const pid_t owner = TemporaryOwner(p.filename().string());
    std::error_code e2;
    if (owner > 0 && ProcessGone(owner)) {
      removed += fs::remove_all(p, e2) > 0 ? 1 : 0;
    } else if (recursive && it->is_directory(e2) && !it->is_symlink(e2)) {
      removed += SweepFolder(p, true);
    }
  }
  return removed;
}

std::string Holder(int fd) {
  std::array<char, 256> buf{};
  const ssize_t n = ::pread(fd, buf.data(), buf.size() - 1, 0);
  std::string s = n > 0 ? std::string(buf.data(), static_cast<size_t>(n)) : std::string();
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s.empty() ? "another perf process" : s;
}

}  // namespace

fs::path WorkspaceLock::PathIn(const fs::path& workspace) { return workspace / ".perf.lock"; }

WorkspaceLock::WorkspaceLock(const fs::path& workspace, std::string_view command) {
  std::error_code ec;
  created_ = !fs::exists(workspace, ec);
  fs::create_directories(workspace, ec);
  if (ec || !fs::is_directory(workspace)) {
    throw IoError(workspace.string(), "cannot create the workspace folder: " + (ec ? ec.message() : "not a folder"),
                  "choose a writable location");
  }
  const fs::path path = PathIn(workspace);
  fd_ = UniqueFd(::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644));
  if (!fd_.valid()) {
    throw IoError(path.string(), StrCat("cannot create the workspace lock: ", std::strerror(errno)),
                  "check that the workspace folder is writable");
  }
  if (::flock(fd_.get(), LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    const std::string holder = Holder(fd_.get());
    if (err == EWOULDBLOCK) {
      throw InputError(path.string(), "lock", holder, "another perf command is writing this workspace",
                       "wait for it to finish (or stop it), or use another workspace folder");
    }
    throw IoError(path.string(), StrCat("cannot lock the workspace: ", std::strerror(err)),
                  "use a workspace on a local file system");
  }
  // Who holds it, for the message a second writer gets. Best effort: the lock is what counts.
  const std::string who = StrCat("pid ", ::getpid(), " (perf ", command, ")\n");
  if (::ftruncate(fd_.get(), 0) == 0) {
    [[maybe_unused]] const ssize_t n = ::pwrite(fd_.get(), who.data(), who.size(), 0);
  }
}

int SweepStaleTemporaries(const fs::path& workspace) {
  int removed = SweepFolder(workspace, false);
  for (const char* owned : {"images", "alpha", "masks", "foreground", "renders", "recon", "preview", "colmap"}) {
    removed += SweepFolder(workspace / owned, true);
  }
  removed += SweepFolder(workspace / "sparse", false);  // perf sfm's model replacement
  return removed;
}

}  // namespace perf
