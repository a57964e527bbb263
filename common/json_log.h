// A file of JSON lines (recon/log.jsonl, perf run --log-json): every line reaches the file as it
// is written, so a killed run keeps each finished line. Header-only (nlohmann::json).
#pragma once

#include <nlohmann/json.hpp>

#include "common/log_file.h"

namespace perf {

class JsonLog {
 public:
  JsonLog() = default;  // writes nothing
  // Appends to `path`, or starts it afresh (append false). `what` names the log in errors.
  JsonLog(const std::filesystem::path& path, bool append, std::string what) : file_(path, append, std::move(what)) {}
  void Write(const nlohmann::json& j) { file_.Write(j.dump() + '\n'); }

 private:
  LogFile file_;
};

}  // namespace perf
