#include "pipeline/progress.h"

#include <unistd.h>

#include <cstdio>

namespace perf {

Progress::Progress(std::string label, bool quiet)
    : label_(std::move(label)),
      quiet_(quiet),
      tty_(::isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()),
      last_(start_ - std::chrono::hours(1)) {}

Progress::~Progress() { Finish(); }

void Progress::Update(int done, int total, const std::string& unit) {
  if (quiet_) return;
  std::lock_guard<std::mutex> lock(mutex_);
  const auto now = std::chrono::steady_clock::now();
  const bool last = done >= total;
  const auto min_gap = tty_ ? std::chrono::milliseconds(100) : std::chrono::milliseconds(5000);
  if (!last && now - last_ < min_gap) return;
  last_ = now;
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double frac = total > 0 ? static_cast<double>(done) / total : 1.0;
  const double eta = done > 0 ? elapsed * (1 - frac) / frac : 0;
  constexpr int kWidth = 30;
  std::string bar(static_cast<size_t>(frac * kWidth + 0.5), '#');
  bar.resize(kWidth, '.');
  std::fprintf(stderr, "%s[%s] %s %d/%d %s %3.0f%%  %.1fs elapsed, ETA %.0fs%s", tty_ ? "\r" : "",
               label_.c_str(), bar.c_str(), done, total, unit.c_str(), frac * 100, elapsed, eta,
               tty_ ? "\033[K" : "\n");
  open_line_ = tty_;
  if (last && tty_) {
    std::fputc('\n', stderr);
    open_line_ = false;
  }
  std::fflush(stderr);
}

void Progress::Message(const std::string& text) {
  if (quiet_) return;
  std::lock_guard<std::mutex> lock(mutex_);
  if (open_line_) std::fputc('\n', stderr);
  open_line_ = false;
  std::fprintf(stderr, "[%s] %s\n", label_.c_str(), text.c_str());
  std::fflush(stderr);
}

void Progress::Finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (open_line_) std::fputc('\n', stderr);
  open_line_ = false;
}

}  // namespace perf
