// Running the steps of `perf sfm` (colmap_runner.h): finding the colmap binary, running one of
// its commands headless with the output logged, and the progress read from that output.
// Internal to sfm_import/.
#pragma once

#include <algorithm>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "common/log_file.h"
#include "sfm_import/colmap_runner.h"

namespace perf::sfm_detail {

// Passes one line of progress to options.progress, when there is one.
void Report(const SfmOptions& options, const std::string& line);

// The colmap binary (`binary`, a name on PATH or a path); throws IoError with an install hint.
std::filesystem::path FindColmap(const std::string& binary);

// What a line of a step's output says about progress, as a short status, or nullopt.
using ProgressParser = std::function<std::optional<std::string>(const std::string& line)>;

struct StepResult {
  int exit_code = 0;             // valid when signal == 0
  int signal = 0;                // the signal that killed the process, or 0
  bool idle = false;             // stopped after printing nothing for options.idle_timeout_seconds
  double idle_timeout_seconds = 0;
  std::deque<std::string> tail;  // last output lines
  bool failed() const { return idle || signal != 0 || exit_code != 0; }
  bool saw(const std::string& needle) const {
    return std::any_of(tail.begin(), tail.end(),
                       [&](const std::string& l) { return l.find(needle) != std::string::npos; });
  }
};

// Runs `colmap <args>` without a shell (paths with spaces or quotes pass through untouched),
// headless, with stdout and stderr through one pipe: every byte is appended to `log` and every
// line is offered to `parse`, whose status is reported at most once a second.
StepResult RunColmapStep(const std::filesystem::path& colmap, const std::vector<std::string>& args,
                         const std::string& stage, const ProgressParser& parse,
                         const SfmOptions& options, LogFile& log);

// Throws IoError for a failed `step`: its exit code or signal and the tail of its log.
[[noreturn]] void ThrowStepFailed(const std::string& step, const StepResult& r,
                                  const std::filesystem::path& log_path);

// COLMAP's steps of one run (perf sfm's, the repair's registration): the binary, one log they all
// append to, and the caller's progress and stop (options.progress, options.check_stop).
class ColmapSteps {
 public:
  ColmapSteps() = default;
  // colmap: FindColmap's; the log is opened (appended to) at log_path.
  ColmapSteps(SfmOptions options, std::filesystem::path colmap, const std::filesystem::path& log_path);

  // Runs `colmap <args>` (RunColmapStep) with this run's log.
  StepResult Run(const std::vector<std::string>& args, const std::string& stage, const ProgressParser& parse);
  // Run, and ThrowStepFailed (named by args.front()) when the step fails.
  void RunOrThrow(const std::vector<std::string>& args, const std::string& stage, const ProgressParser& parse);

  const std::filesystem::path& colmap() const { return colmap_; }
  const std::filesystem::path& log_path() const { return log_.path(); }

 private:
  SfmOptions options_;
  std::filesystem::path colmap_;
  LogFile log_;
};

// Progress parsers for the steps (COLMAP 3.8 output).
ProgressParser ExtractionParser();
ProgressParser ExhaustiveParser();
ProgressParser SequentialParser();
ProgressParser MapperParser(int num_images);

}  // namespace perf::sfm_detail
