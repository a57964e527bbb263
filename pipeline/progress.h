// Progress on long work: a one-line bar redrawn in place on a terminal, a line every few
// seconds otherwise (logs, CI), nothing when quiet.
#pragma once

#include <chrono>
#include <mutex>
#include <string>

namespace perf {

class Progress {
 public:
  // `label` prefixes every line, e.g. "import".
  explicit Progress(std::string label, bool quiet = false);
  ~Progress();

  // Thread-safe; cheap to call often (redraws at most ~10 times a second).
  void Update(int done, int total, const std::string& unit);
  // A free-form status line (e.g. the stage of an external tool).
  void Message(const std::string& text);
  // Ends the in-place line, if one is drawn.
  void Finish();

 private:
  std::string label_;
  bool quiet_, tty_, open_line_ = false;
  std::chrono::steady_clock::time_point start_, last_;
  std::mutex mutex_;
};

}  // namespace perf
