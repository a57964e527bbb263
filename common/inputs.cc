#include "common/inputs.h"

#include <sys/stat.h>

#include <map>
#include <mutex>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/errors.h"

namespace fs = std::filesystem;

namespace perf {
namespace {

// Inputs by device and inode, with the path they were registered under: a registered file that
// is gone (its inode may be reused by a new file) no longer protects anything.
struct Protected {
  std::mutex mutex;
  std::map<std::pair<dev_t, ino_t>, fs::path> files;
};
Protected& ProtectedInputs() {
  static Protected p;
  return p;
}

// The registered input at `target`'s inode, or an empty path.
fs::path InputAt(const fs::path& target) {
  struct stat st {};
  if (::stat(target.c_str(), &st) != 0) return {};  // nothing there yet: cannot be an input
  Protected& p = ProtectedInputs();
  std::lock_guard lock(p.mutex);
  const auto it = p.files.find({st.st_dev, st.st_ino});
  struct stat input {};
  if (it != p.files.end() && ::stat(it->second.c_str(), &input) == 0 && input.st_dev == st.st_dev &&
      input.st_ino == st.st_ino) {
    return it->second;
  }
  return {};
}

}  // namespace

void ProtectInput(const fs::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return;
  std::error_code ec;
  const fs::path absolute = fs::absolute(path, ec);
  Protected& p = ProtectedInputs();
  std::lock_guard lock(p.mutex);
  p.files[{st.st_dev, st.st_ino}] = ec ? path : absolute;
}

void ProtectInputFolder(const fs::path& dir, int limit) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return;
  int count = 0;
  for (fs::recursive_directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec), end;
       !ec && it != end && count < limit; it.increment(ec)) {
    std::error_code e2;
    if (it->is_regular_file(e2) && !it->is_symlink(e2)) {
      ProtectInput(it->path());
      ++count;
    }
  }
}

bool IsProtectedInput(const fs::path& path) { return !InputAt(path).empty(); }

void CheckNotInput(const fs::path& target, std::string_view what) {
  const fs::path input = InputAt(target);
  if (input.empty()) return;
  throw InputError(target.string(), "", "",
                   StrCat(what, " would change an input file (", input.string(), ", a photo or model PERF reads)"),
                   "inputs are never modified: choose a workspace or output folder that does not hold the photos "
                   "or models, e.g. a new folder beside them");
}

std::vector<fs::path> ProtectedInputPaths() {
  Protected& p = ProtectedInputs();
  std::lock_guard lock(p.mutex);
  std::vector<fs::path> paths;
  for (const auto& [id, path] : p.files) paths.push_back(path);
  return paths;
}

fs::path InputRecordPath(const fs::path& workspace) { return workspace / "inputs.json"; }

void WriteInputRecord(const fs::path& workspace) {
  nlohmann::json files = nlohmann::json::array();
  for (const fs::path& p : ProtectedInputPaths()) files.push_back(p.string());
  const nlohmann::json record{{"format", "perf-inputs"}, {"version", 1}, {"files", files}};
  WriteFileAtomically(InputRecordPath(workspace), record.dump(1) + "\n");
}

int ProtectRecordedInputs(const fs::path& workspace) {
  const fs::path path = InputRecordPath(workspace);
  std::error_code ec;
  if (!fs::exists(path, ec)) return 0;
  nlohmann::json record;
  try {
    record = nlohmann::json::parse(ReadFileToString(path));
  } catch (const nlohmann::json::exception& e) {
    throw InputError(path.string(), "", "", StrCat("not a valid record of the workspace's inputs: ", e.what()),
                     "re-run perf import, which writes it");
  }
  if (!record.is_object() || !record.contains("files") || !record["files"].is_array()) {
    throw InputError(path.string(), "files", "", "missing: not a record of the workspace's inputs",
                     "re-run perf import, which writes it");
  }
  int count = 0;
  for (const auto& f : record["files"]) {
    if (!f.is_string()) continue;
    ProtectInput(f.get<std::string>());
    ++count;
  }
  return count;
}

std::string RecordedPath(const std::filesystem::path& given) {
  return std::filesystem::absolute(given).lexically_normal().string();
}

bool RecordedAs(const std::string& recorded, const std::filesystem::path& given) {
  std::error_code ec;
  return recorded == RecordedPath(given) || std::filesystem::equivalent(recorded, given, ec);
}

}  // namespace perf
