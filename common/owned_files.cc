#include "common/owned_files.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/errors.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

// What an entry says PERF made at its path. kFile: a finished file, unchanged since (size and
// modification time too); kLog: a file PERF appends to; kFolder: a folder PERF made; kWork: a
// folder whose whole content is PERF's (a program PERF runs writes it); kTemp: a temporary of
// process `pid`, file or folder.
enum class Kind { kFile, kLog, kFolder, kWork, kTemp };
constexpr const char* kKindNames[] = {"file", "log", "folder", "work", "temp"};

struct Entry {
  Kind kind = Kind::kFile;
  dev_t dev = 0;
  ino_t ino = 0;
  int64_t size = 0, mtime_ns = 0;
  pid_t pid = 0;
};

std::optional<struct stat> Lstat(const fs::path& p) {
  struct stat st {};
  if (::lstat(p.c_str(), &st) != 0) return std::nullopt;
  return st;
}

int64_t MtimeNs(const struct stat& st) { return int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec; }

Entry EntryOf(Kind kind, const struct stat& st) {
  return Entry{kind, st.st_dev, st.st_ino, static_cast<int64_t>(st.st_size), MtimeNs(st), ::getpid()};
}

// Whether `st` (a path's lstat) is the thing `e` recorded. A finished file is known by its size
// and modification time to the nanosecond, which a copy of the workspace keeps (cp -a, rsync -a)
// and an edit does not; a log also by its inode while PERF appends to it; a folder or a
// temporary by its inode alone.
bool Matches(const Entry& e, const struct stat& st) {
  if (S_ISLNK(st.st_mode)) return false;
  const bool same_inode = e.dev == st.st_dev && e.ino == st.st_ino;
  const bool same_content = e.size == st.st_size && e.mtime_ns == MtimeNs(st);
  switch (e.kind) {
    case Kind::kFile: return S_ISREG(st.st_mode) && same_content;
    case Kind::kLog: return S_ISREG(st.st_mode) && (same_inode || same_content);
    case Kind::kFolder:
    case Kind::kWork: return S_ISDIR(st.st_mode) && same_inode;
    case Kind::kTemp: return (S_ISREG(st.st_mode) || S_ISDIR(st.st_mode)) && same_inode;
  }
  return false;
}

bool ProcessGone(pid_t pid) { return pid > 0 && pid != ::getpid() && ::kill(pid, 0) != 0 && errno == ESRCH; }

nlohmann::json ToJson(const std::string& key, const Entry& e) {
  return {{"k", kKindNames[static_cast<int>(e.kind)]}, {"p", key}, {"d", e.dev}, {"i", e.ino},
          {"s", e.size}, {"m", e.mtime_ns}, {"pid", e.pid}};
}

// One journal line; nullopt for a line that is not one (torn by a crash: what it named is not ours).
std::optional<std::pair<std::string, Entry>> FromJson(const std::string& line) {
  try {
    const nlohmann::json j = nlohmann::json::parse(line);
    Entry e;
    const std::string kind = j.at("k").get<std::string>();
    int k = 0;
    while (k < 5 && kind != kKindNames[k]) ++k;
    if (k == 5) return std::nullopt;
    e.kind = static_cast<Kind>(k);
    e.dev = j.at("d").get<dev_t>();
    e.ino = j.at("i").get<ino_t>();
    e.size = j.at("s").get<int64_t>();
    e.mtime_ns = j.at("m").get<int64_t>();
    e.pid = j.at("pid").get<pid_t>();
    return std::pair{j.at("p").get<std::string>(), e};
  } catch (const nlohmann::json::exception&) {
    return std::nullopt;
  }
}

class Record {
 public:
  explicit Record(const fs::path& workspace)
      : root_(fs::absolute(workspace).lexically_normal()), journal_(PrivateFolder(root_) / "owned.jsonl") {
    Open();
    Load();
  }

  std::string Key(const fs::path& p) const {
    const fs::path a = fs::absolute(p).lexically_normal();
    const fs::path rel = a.lexically_relative(root_);
    if (!rel.empty() && *rel.begin() != ".." && rel != ".") return rel.generic_string();
    return a.string();
  }
  fs::path PathOf(const std::string& key) const { return fs::path(key).is_absolute() ? fs::path(key) : root_ / key; }

  // The entry at `p` that matches what is there now.
  std::optional<Entry> Find(const fs::path& p, const struct stat& st) {
    std::lock_guard lock(mutex_);
    const auto [begin, end] = entries_.equal_range(Key(p));
    for (auto it = begin; it != end; ++it) {
      if (Matches(it->second, st)) return it->second;
    }
    return std::nullopt;
  }

  // The first folder between the workspace and `p` (a path inside it) that is a symbolic link:
  // writing through it would put a file outside the workspace. Empty when there is none or `p`
  // is not inside the workspace.
  fs::path LinkOnTheWay(const fs::path& p) const {
    const fs::path rel = fs::absolute(p).lexically_normal().lexically_relative(root_);
    if (rel.empty() || *rel.begin() == "..") return {};
    fs::path dir = root_;
    for (const fs::path& part : rel.parent_path()) {
      dir /= part;
      const auto st = Lstat(dir);
      if (!st) return {};
      if (S_ISLNK(st->st_mode)) return dir;
    }
    return {};
  }

  // Whether a folder above `p`, inside the workspace, is a work folder of PERF's.
  bool InWorkFolder(const fs::path& p) {
    fs::path a = fs::absolute(p).lexically_normal();
    for (fs::path dir = a.parent_path(); dir != root_ && dir.has_relative_path() && dir != dir.parent_path();
         dir = dir.parent_path()) {
      const auto st = Lstat(dir);
      if (!st) return false;
      if (const auto e = Find(dir, *st); e && e->kind == Kind::kWork) return true;
    }
    return false;
  }

  void Add(const fs::path& p, const Entry& e) {
    const std::string key = Key(p);
    const std::string line = ToJson(key, e).dump() + "\n";
    std::lock_guard lock(mutex_);
    // One write of one line to an O_APPEND file: lines of several threads never interleave.
    const ssize_t n = ::write(fd_.get(), line.data(), line.size());
    if (n != static_cast<ssize_t>(line.size())) {
      throw IoError(journal_.string(), StrCat("cannot record what PERF writes: ", n < 0 ? std::strerror(errno) : "short write"),
                    "check the free disk space and that the workspace is writable");
    }
    entries_.emplace(key, e);
  }

  int Sweep() {
    int removed = 0;
    std::lock_guard lock(mutex_);
    for (const auto& [key, e] : entries_) {
      if (e.kind != Kind::kTemp || !ProcessGone(e.pid)) continue;
      const fs::path p = PathOf(key);
      const auto st = Lstat(p);
      std::error_code ec;
      if (st && Matches(e, *st) && fs::remove_all(p, ec) > 0) ++removed;
    }
    Compact();
    return removed;
  }

 private:
  void Open() {
    fd_ = UniqueFd(::open(journal_.c_str(), O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644));
    if (!fd_.valid()) {
      throw IoError(journal_.string(), StrCat("cannot open the record of what PERF wrote: ", std::strerror(errno)),
                    "check that the workspace is writable (and that this is not a link)");
    }
  }
  void Load() {
    UniqueFd in(::open(journal_.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW));
    std::string text, line;
    char buf[65536];
    for (ssize_t n; in.valid() && (n = ::read(in.get(), buf, sizeof buf)) > 0;) text.append(buf, static_cast<size_t>(n));
    size_t start = 0;
    while (start < text.size()) {
      size_t end = text.find('\n', start);
      if (end == std::string::npos) break;  // a torn last line
      if (auto kv = FromJson(text.substr(start, end - start))) entries_.emplace(std::move(kv->first), kv->second);
      start = end + 1;
    }
  }
  // Keeps the entries that still name what is there (and live processes' temporaries). Best
  // effort: when the new journal cannot be written, the old one (a superset) stays.
  void Compact() {
    std::multimap<std::string, Entry> kept;
    std::string text;
    for (const auto& [key, e] : entries_) {
      const auto st = Lstat(PathOf(key));
      const bool live_temp = e.kind == Kind::kTemp && !ProcessGone(e.pid) && st && Matches(e, *st);
      if (live_temp || (e.kind != Kind::kTemp && st && Matches(e, *st))) {
        kept.emplace(key, e);
        text += ToJson(key, e).dump() + "\n";
      }
    }
    if (kept.size() == entries_.size()) return;
    const fs::path next = journal_.string() + ".next";
    UniqueFd out(::open(next.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_NOFOLLOW, 0644));
    const bool written = out.valid() && ::write(out.get(), text.data(), text.size()) == static_cast<ssize_t>(text.size()) &&
                         ::fsync(out.get()) == 0 && out.Close() && ::rename(next.c_str(), journal_.c_str()) == 0;
    if (!written) {
      ::unlink(next.c_str());
      return;
    }
    entries_ = std::move(kept);
    Open();
  }

  fs::path root_, journal_;
  UniqueFd fd_;
  std::mutex mutex_;
  std::multimap<std::string, Entry> entries_;
};

std::unique_ptr<Record>& Installed() {
  static std::unique_ptr<Record> record;
  return record;
}

const char kNotOursHint[] =
    "PERF replaces only files it wrote itself (WORKSPACE/.perf/owned.jsonl records them); choose another path, or "
    "move the file away yourself if it is an output of an older PERF you no longer need";

void Journal(const fs::path& p, Kind kind) {
  Record* r = Installed().get();
  if (r == nullptr) return;
  const auto st = Lstat(p);
  if (!st) throw IoError(p.string(), StrCat("vanished right after PERF made it: ", std::strerror(errno)));
  r->Add(p, EntryOf(kind, *st));
}

}  // namespace

fs::path PrivateFolder(const fs::path& workspace) { return workspace / ".perf"; }

void UseOwnershipRecord(const fs::path& workspace) {
  const fs::path dir = PrivateFolder(workspace);
  if (::mkdir(dir.c_str(), 0755) != 0 && errno != EEXIST) {
    throw IoError(dir.string(), StrCat("cannot make PERF's folder in the workspace: ", std::strerror(errno)),
                  "check that the workspace is writable");
  }
  const auto st = Lstat(dir);
  if (!st || !S_ISDIR(st->st_mode)) {
    throw InputError(dir.string(), "", "", "not a folder (PERF keeps its record of what it wrote there)",
                     "move it away, or choose another workspace folder");
  }
  Installed() = std::make_unique<Record>(workspace);
}

bool HasOwnershipRecord() { return Installed() != nullptr; }
void DropOwnershipRecord() { Installed().reset(); }

bool IsOwned(const fs::path& path) {
  Record* r = Installed().get();
  if (r == nullptr) return true;
  const auto st = Lstat(path);
  if (!st) return false;
  if (r->Find(path, *st)) return true;
  return !S_ISLNK(st->st_mode) && r->InWorkFolder(path);
}

void CheckNoLinkOnTheWay(const fs::path& path) {
  Record* r = Installed().get();
  if (r == nullptr) return;
  const fs::path link = r->LinkOnTheWay(path);
  if (link.empty()) return;
  std::error_code ec;
  throw InputError(link.string(), "", "",
                   StrCat("this folder of the workspace is a symbolic link (to ", fs::read_symlink(link, ec).string(),
                          "), so what PERF writes there would land outside the workspace"),
                   "PERF writes only into the workspace's own folders: remove the link (PERF makes the folder again), "
                   "or choose another workspace");
}

void CheckReplaceable(const fs::path& target, std::string_view what) {
  CheckNoLinkOnTheWay(target);
  const auto st = Lstat(target);
  if (!st || IsOwned(target)) return;
  const char* kind = S_ISLNK(st->st_mode) ? "a symbolic link" : S_ISDIR(st->st_mode) ? "a folder" : "a file";
  throw InputError(target.string(), "", "",
                   StrCat(what, " would change ", kind, " that PERF did not write (or that changed since)"),
                   kNotOursHint);
}

void RecordTemporary(const fs::path& tmp) { Journal(tmp, Kind::kTemp); }
void RecordFolder(const fs::path& dir) { Journal(dir, Kind::kFolder); }
void RecordWorkFolder(const fs::path& dir) { Journal(dir, Kind::kWork); }

void RecordOutput(const fs::path& final_path, const fs::path& written) {
  Record* r = Installed().get();
  if (r == nullptr) return;
  const auto st = Lstat(written);
  if (!st) throw IoError(final_path.string(), StrCat("the written file is gone: ", std::strerror(errno)));
  r->Add(final_path, EntryOf(S_ISDIR(st->st_mode) ? Kind::kWork : Kind::kFile, *st));
}

void ReadBackAsOwned(const fs::path& path, const std::function<void()>& read) {
  const auto before = Lstat(path);
  read();
  Record* r = Installed().get();
  const auto after = Lstat(path);
  if (r == nullptr || !before || !after || !S_ISREG(before->st_mode) || r->Find(path, *after)) return;
  const Entry now = EntryOf(Kind::kFile, *after);
  if (Matches(now, *before)) r->Add(path, now);
}

void MoveOwned(const fs::path& from, const fs::path& to) {
  Record* r = Installed().get();
  const auto st = Lstat(from);
  std::optional<Entry> e;
  if (r != nullptr) {
    if (!st || !(e = r->Find(from, *st))) CheckReplaceable(from, "moving it");
    CheckReplaceable(to, "moving a file of PERF's there");
  }
  if (r != nullptr && st) {
    // Journalled at its new path first: a kill between the two leaves an entry naming nothing
    // (dropped later), never a moved file the record does not know.
    Entry moved = e ? *e : EntryOf(S_ISDIR(st->st_mode) ? Kind::kWork : Kind::kFile, *st);
    if (moved.kind == Kind::kTemp) moved.kind = S_ISDIR(st->st_mode) ? Kind::kWork : Kind::kFile;
    r->Add(to, moved);
  }
  std::error_code ec;
  fs::rename(from, to, ec);
  if (ec) throw IoError(from.string(), "cannot move it to " + to.string() + ": " + ec.message(), "check that the workspace is writable");
}

void RemoveOwned(const fs::path& path) {
  if (!Lstat(path)) return;
  CheckReplaceable(path, "removing it");
  std::error_code ec;
  fs::remove_all(path, ec);
  if (ec) throw IoError(path.string(), "cannot remove it: " + ec.message(), "check that the workspace is writable");
}

bool RemoveOwnedTree(const fs::path& dir) {
  const auto st = Lstat(dir);
  if (!st) return true;
  std::error_code ec;
  if (!S_ISDIR(st->st_mode)) {
    if (IsOwned(dir)) fs::remove(dir, ec);
    return !Lstat(dir);
  }
  if (Record* r = Installed().get(); r != nullptr) {
    if (const auto e = r->Find(dir, *st); e && (e->kind == Kind::kWork || e->kind == Kind::kTemp)) {
      fs::remove_all(dir, ec);  // a work folder or a temporary one: all of it is PERF's
      return !Lstat(dir);
    }
  }
  std::vector<fs::path> children;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) children.push_back(it->path());
  for (const fs::path& c : children) RemoveOwnedTree(c);
  if (IsOwned(dir)) fs::remove(dir, ec);  // only when empty
  return !Lstat(dir);
}

UniqueFd OpenLog(const fs::path& path, bool append, std::string_view what) {
  const auto before = Lstat(path);
  if (before) {
    CheckReplaceable(path, StrCat("the ", what));
    if (!S_ISREG(before->st_mode)) {
      throw InputError(path.string(), "", "", StrCat("the ", what, " is not a regular file"), "choose another path");
    }
  }
  // An existing log is opened only if it is still the file checked; a new one is made here (O_EXCL).
  const int flags = O_WRONLY | O_APPEND | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK;
  UniqueFd fd(::open(path.c_str(), before ? flags : flags | O_CREAT | O_EXCL, 0644));
  if (!fd.valid()) {
    throw IoError(path.string(), StrCat("cannot open the ", what, " for writing: ", std::strerror(errno)),
                  "check that the folder is writable");
  }
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0 || !S_ISREG(st.st_mode) ||
      (before && (before->st_ino != st.st_ino || before->st_dev != st.st_dev))) {
    throw InputError(path.string(), "", "", StrCat("the ", what, " changed while PERF opened it"), "run again");
  }
  if (before && !append && ::ftruncate(fd.get(), 0) != 0) {
    throw IoError(path.string(), StrCat("cannot start the ", what, " afresh: ", std::strerror(errno)));
  }
  if (Record* r = Installed().get(); r != nullptr && !r->Find(path, st)) r->Add(path, EntryOf(Kind::kLog, st));
  return fd;
}

void RecordLogWritten(const fs::path& path, int fd) {
  Record* r = Installed().get();
  struct stat st {};
  if (r == nullptr || ::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) return;
  r->Add(path, EntryOf(Kind::kLog, st));
}

int SweepOwnedTemporaries() {
  Record* r = Installed().get();
  return r == nullptr ? 0 : r->Sweep();
}

}  // namespace perf
