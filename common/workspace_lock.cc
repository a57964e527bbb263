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
#include "common/inputs.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

const std::regex& TemporaryPattern() {
  static const std::regex kTemp(R"(\.tmp([0-9]{1,9})-[0-9]+)");
  return kTemp;
}

// The pid in a temporary's name (atomic_file.h's TempPathFor), or 0 if it is not one.
pid_t TemporaryOwner(const std::string& name) {
  std::smatch m;
  if (!std::regex_search(name, m, TemporaryPattern())) return 0;
  return static_cast<pid_t>(std::stol(m[1].str()));
}

// Whether `name` is a temporary of one of the files PERF writes in the workspace's top level,
// where a user's own files may lie (a workspace laid over the photos).
bool TopLevelTemporary(const std::string& name) {
  const std::string target = std::regex_replace(name, TemporaryPattern(), "", std::regex_constants::format_first_only);
  for (const char* output : {"scene.json", "inputs.json", "export.json", "report.json", "report.html", "run.json",
                             "volume.vdb", "mesh.ply", "mesh.obj", "mesh.glb"}) {
    if (target == output) return true;
  }
  return false;
}

bool ProcessGone(pid_t pid) { return pid != ::getpid() && ::kill(pid, 0) != 0 && errno == ESRCH; }

// only_outputs: only the temporaries of PERF's top-level outputs (TopLevelTemporary).
int SweepFolder(const fs::path& dir, bool recursive, bool only_outputs = false) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec) || fs::is_symlink(dir, ec)) return 0;
  int removed = 0;
  for (fs::directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec), end; !ec && it != end;
       it.increment(ec)) {
    const fs::path p = it->path();
    const pid_t owner = TemporaryOwner(p.filename().string());
    std::error_code e2;
    if (owner > 0 && ProcessGone(owner) && (!only_outputs || TopLevelTemporary(p.filename().string())) &&
        !IsProtectedInput(p)) {
      removed += fs::remove_all(p, e2) > 0 ? 1 : 0;
    } else if (recursive && it->is_directory(e2) && !it->is_symlink(e2)) {
      removed += SweepFolder(p, true);
    }
  }
  return removed;
}

// Who holds the lock, from its note (.perf.lock).
std::string Holder(const fs::path& info) {
  std::array<char, 256> buf{};
  const UniqueFd fd(::open(info.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOFOLLOW));
  const ssize_t n = fd.valid() ? ::pread(fd.get(), buf.data(), buf.size() - 1, 0) : 0;
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
  // Who holds it, for the message a second writer gets. Best effort: the lock is what counts.
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
}

int SweepStaleTemporaries(const fs::path& workspace) {
  int removed = SweepFolder(workspace, false, true);
  for (const char* owned : {"images", "alpha", "masks", "foreground", "renders", "recon", "preview", "colmap"}) {
    removed += SweepFolder(workspace / owned, true);
  }
  removed += SweepFolder(workspace / "sparse", false);  // perf sfm's model replacement
  return removed;
}

}  // namespace perf
