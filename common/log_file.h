// A log PERF writes line by line (recon/log.jsonl, colmap/colmap.log, perf run --log-json):
// opened with OpenLog (owned_files.h: never through a link, an existing file only if PERF made
// it), every write checked and going straight to the file, so a killed run keeps what it wrote.
#pragma once

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>

#include "common/errors.h"
#include "common/inputs.h"
#include "common/owned_files.h"

namespace perf {

class LogFile {
 public:
  LogFile() = default;  // writes nothing
  ~LogFile() {
    if (fd_.valid()) RecordLogWritten(path_, fd_.get());
  }
  LogFile(LogFile&&) = default;
  LogFile& operator=(LogFile&&) = default;
  // Appends to `path`, or starts it afresh (append false). `what` names the log in errors.
  LogFile(const std::filesystem::path& path, bool append, std::string what) : path_(path), what_(std::move(what)) {
    CheckNotInput(path, "the " + what_);
    fd_ = OpenLog(path, append, what_);
  }
  bool is_open() const { return fd_.valid(); }
  const std::filesystem::path& path() const { return path_; }

  void Write(std::string_view text) {
    while (fd_.valid() && !text.empty()) {
      const ssize_t n = ::write(fd_.get(), text.data(), text.size());
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        throw IoError(path_.string(), StrCat("cannot write the ", what_, ": ", n < 0 ? std::strerror(errno) : "no progress"),
                      "check the free disk space");
      }
      text.remove_prefix(static_cast<size_t>(n));
    }
  }

 private:
  std::filesystem::path path_;
  std::string what_;
  UniqueFd fd_;
};

}  // namespace perf
