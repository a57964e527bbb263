// One writer per workspace (DESIGN.md "Safety"): every command that writes a workspace holds an
// advisory flock(2) on the workspace folder while it runs (WORKSPACE/.perf/lock names the holder
// and is removed when it is done). The kernel drops the lock when the process ends, however it
// ends, so a killed run never leaves a stale lock behind.
#pragma once

#include <filesystem>
#include <string_view>

#include "common/unique_fd.h"

namespace perf {

class WorkspaceLock {
 public:
  // Creates the workspace folder when it does not exist and takes the lock without waiting.
  // Throws InputError naming the holder's pid and command when another process holds it.
  WorkspaceLock(const std::filesystem::path& workspace, std::string_view command);
  ~WorkspaceLock();
  WorkspaceLock(const WorkspaceLock&) = delete;
  WorkspaceLock& operator=(const WorkspaceLock&) = delete;

  // Whether the workspace folder was made by this lock (it did not exist before).
  bool created_workspace() const { return created_; }
  static std::filesystem::path PathIn(const std::filesystem::path& workspace);

 private:
  UniqueFd fd_;  // the workspace folder; closing it releases the flock
  std::filesystem::path info_;  // .perf/lock
  bool created_ = false, created_private_ = false;
};

}  // namespace perf
