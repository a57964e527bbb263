// A file of JSON lines (recon/log.jsonl, perf run --log-json): every line is flushed as it is
// written, so a killed run keeps each finished line. Header-only (nlohmann::json).
#pragma once

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "common/errors.h"
#include "common/inputs.h"

namespace perf {

class JsonLog {
 public:
  JsonLog() = default;  // writes nothing
  // Appends to `path`, or starts it afresh (append false). `what` names the log in errors.
  JsonLog(const std::filesystem::path& path, bool append, std::string what) : path_(path), what_(std::move(what)) {
    CheckNotInput(path, "the " + what_);
    out_.open(path, append ? std::ios::app : std::ios::trunc);
    if (!out_) throw IoError(path.string(), "cannot write the " + what_, "check that the folder is writable");
  }
  void Write(const nlohmann::json& j) {
    if (!out_.is_open()) return;
    out_ << j.dump() << '\n';
    out_.flush();
    if (!out_) throw IoError(path_.string(), "cannot write the " + what_, "check the free disk space");
  }

 private:
  std::filesystem::path path_;
  std::string what_;
  std::ofstream out_;
};

}  // namespace perf
