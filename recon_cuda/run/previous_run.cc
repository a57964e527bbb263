#include "recon_cuda/run/previous_run.h"

#include <string>
#include <vector>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/owned_files.h"
#include "recon_cuda/data/checkpoint.h"

namespace fs = std::filesystem;

namespace perf::recon {
namespace {

// The files of a run in recon/: checkpoints (checkpoint.h's names), recon.json, log.jsonl and
// settings.json (run_settings.h).
bool IsRunFile(const fs::path& p) {
  const std::string name = p.filename().string();
  return name == "recon.json" || name == "log.jsonl" || name == "settings.json" ||
         (name.rfind("level_", 0) == 0 && p.extension() == ".perfvol");
}

std::vector<fs::path> RunFiles(const fs::path& dir) {
  std::vector<fs::path> files;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_regular_file(ec) && IsRunFile(it->path())) files.push_back(it->path());
  }
  return files;
}

bool HasCheckpoint(const fs::path& dir) {
  for (const fs::path& p : RunFiles(dir)) {
    if (p.extension() == ".perfvol") return true;
  }
  return false;
}

// Throws InputError if a run file of `dir` is a user's input (inputs.h) or any file PERF did not
// write (owned_files.h): it is neither moved nor removed (e.g. a NeRF json that lies at
// recon/recon.json, or a run of an older PERF that kept no record).
void CheckOurs(const fs::path& dir) {
  for (const fs::path& p : RunFiles(dir)) CheckMayReplace(p, "moving the previous run's files aside");
}

// Moves every run file of `from` into `to`, replacing what is there.
void MoveRunFiles(const fs::path& from, const fs::path& to) {
  for (const fs::path& p : RunFiles(from)) MoveOwned(p, to / p.filename());
}

// This run's own files, before the previous run's come back.
void RemoveRunFiles(const fs::path& dir) {
  for (const fs::path& p : RunFiles(dir)) RemoveOwned(p);
}

}  // namespace

PreviousRun::PreviousRun(const fs::path& workspace) : recon_(workspace / "recon"), aside_(recon_ / "previous") {
  if (RunFiles(recon_).empty()) return;
  CheckOurs(recon_);
  RemoveOwnedTree(aside_);
  EnsureWritableDirectory(aside_);
  MoveRunFiles(recon_, aside_);
  active_ = true;
}

PreviousRun::~PreviousRun() {
  if (!active_) return;
  try {
    RemoveRunFiles(recon_);
    MoveRunFiles(aside_, recon_);
    RemoveOwnedTree(aside_);
  } catch (const Error&) {
    // Left in recon/previous/: the next reconstruct puts them back (RecoverPreviousRun).
  }
}

void PreviousRun::Discard() {
  if (!active_) return;
  active_ = false;
  RemoveOwnedTree(aside_);
}

void RecoverPreviousRun(const fs::path& workspace) {
  const fs::path recon = workspace / "recon", aside = recon / "previous";
  std::error_code ec;
  if (!fs::is_directory(aside, ec)) return;
  CheckOurs(recon);
  CheckOurs(aside);
  if (!HasCheckpoint(recon)) {
    RemoveRunFiles(recon);
    MoveRunFiles(aside, recon);
  }
  RemoveOwnedTree(aside);
}

}  // namespace perf::recon
