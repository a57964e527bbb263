#include "sfm_import/colmap_process.h"

#include <signal.h>

#include <chrono>
#include <cstring>
#include <ctime>
#include <regex>
#include <string_view>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/subprocess.h"

namespace fs = std::filesystem;

namespace perf::sfm_detail {
namespace {

using Clock = std::chrono::steady_clock;

constexpr size_t kLogTailLines = 15;

std::string Timestamp() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  ::localtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S", &tm);
  return buf;
}

// Removes glog's files ("colmap.*", after the program's name) from `dir`, PERF's work folder.
void RemoveGlogFiles(const fs::path& dir) {
  std::error_code ec;
  std::vector<fs::path> files;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->path().filename().string().rfind("colmap.", 0) == 0) files.push_back(it->path());
  }
  for (const fs::path& f : files) fs::remove(f, ec);
}

}  // namespace

void Report(const SfmOptions& options, const std::string& line) {
  if (options.progress) options.progress(line);
}

ColmapSteps::ColmapSteps(SfmOptions options, fs::path colmap, const fs::path& log_path)
    : options_(std::move(options)), colmap_(std::move(colmap)), log_(log_path, true, "COLMAP log") {}

StepResult ColmapSteps::Run(const std::vector<std::string>& args, const std::string& stage,
                            const ProgressParser& parse) {
  return RunColmapStep(colmap_, args, stage, parse, options_, log_);
}

void ColmapSteps::RunOrThrow(const std::vector<std::string>& args, const std::string& stage,
                             const ProgressParser& parse) {
  const StepResult r = Run(args, stage, parse);
  if (r.failed()) ThrowStepFailed(args.front(), r, log_.path());
}

fs::path FindColmap(const std::string& binary) {
  return FindExecutable(binary,
                        "install COLMAP (`sudo apt-get install colmap`, or run scripts/setup.sh), or pass its path "
                        "with --colmap-binary");
}

StepResult RunColmapStep(const fs::path& colmap, const std::vector<std::string>& args,
                         const std::string& stage, const ProgressParser& parse,
                         const SfmOptions& options, LogFile& log) {
  const std::string command_line = CommandLine(colmap, args);
  // A prefix of our own: COLMAP's headings are lines of '=' already.
  log.Write(StrCat("\n[perf ", Timestamp(), "] run: ", command_line, "\n"));

  StepResult result;
  std::string partial;
  std::string pending_status;
  Clock::time_point last_report = Clock::now();
  auto handle_line = [&](std::string line) {
    if (line.empty()) return;
    if (auto status = parse ? parse(line) : std::nullopt) pending_status = *status;
    if (!pending_status.empty() && Clock::now() - last_report >= std::chrono::seconds(1)) {
      Report(options, stage + ": " + pending_status);
      pending_status.clear();
      last_report = Clock::now();
    }
    result.tail.push_back(std::move(line));
    if (result.tail.size() > kLogTailLines) result.tail.pop_front();
  };
  // COLMAP links Qt even for its CLI commands; without a display, Qt aborts unless told to use
  // the offscreen platform.
  const auto on_output = [&](std::string_view chunk) {
    if (options.check_stop) options.check_stop();
    log.Write(chunk);  // as it comes, so the log is useful while a long step runs
    for (const char c : chunk) {
      // COLMAP rewrites some lines with '\r'; either ends a line for us.
      if (c == '\n' || c == '\r') {
        handle_line(std::move(partial));
        partial.clear();
      } else if (partial.size() < 4096) {  // bounded even if a tool never ends a line
        partial += c;
      }
    }
  };
  // COLMAP's glog (and Ceres's) also writes every step's lines to files of its own, in /tmp unless
  // told otherwise: they go to a work folder beside our log, emptied after the step (our log has
  // the same lines).
  const fs::path glog_dir = log.path().parent_path() / "glog";
  EnsureWorkFolder(glog_dir);
  const ProcessResult process = RunProcess(colmap, args, {"QT_QPA_PLATFORM=offscreen", "GLOG_log_dir=" + glog_dir.string()},
                                           on_output, options.idle_timeout_seconds);
  RemoveGlogFiles(glog_dir);
  handle_line(std::move(partial));
  // The last status of a step (e.g. 12/12 images) is worth showing even if it came fast.
  if (!pending_status.empty()) Report(options, stage + ": " + pending_status);
  result.exit_code = process.exit_code;
  result.signal = process.signal;
  result.idle = process.idle;
  result.idle_timeout_seconds = options.idle_timeout_seconds;
  log.Write(StrCat("[perf ", Timestamp(), "] ",
                   result.idle     ? StrCat("stopped: no output for ", options.idle_timeout_seconds, " s")
                   : result.signal ? StrCat("killed by signal ", result.signal)
                                   : StrCat("exit code ", result.exit_code),
                   "\n"));
  return result;
}

[[noreturn]] void ThrowStepFailed(const std::string& step, const StepResult& r,
                                  const fs::path& log_path) {
  std::string problem = r.idle     ? StrCat("colmap ", step, " printed nothing for ", r.idle_timeout_seconds,
                                            " s and was stopped (it looks stuck)")
                        : r.signal ? StrCat("colmap ", step, " was killed by signal ", r.signal, " (",
                                            strsignal(r.signal), ")")
                                   : StrCat("colmap ", step, " failed with exit code ", r.exit_code);
  problem += StrCat("; last lines of ", log_path.string(), ":");
  for (const auto& line : r.tail) problem += "\n  | " + line;
  std::string hint = StrCat("see the full log in ", log_path.string());
  if (r.idle) {
    hint += "; run again (a stuck step is often a one-off), or if the step is only slow, raise "
            "--colmap-idle-timeout";
  } else if (r.signal == SIGKILL) {
    hint += "; a kill by signal 9 is often the out-of-memory killer: try a smaller --max-image-size";
  }
  throw IoError(log_path.string(), problem, hint);
}

// --------------------------------------------------------------------------------------------
// Progress parsers for the three steps (COLMAP 3.8 output).

// "<done>/<total> images" from the two numbers `re` captures.
static ProgressParser ImageCountParser(const std::regex& re) {
  return [&re](const std::string& line) -> std::optional<std::string> {
    std::smatch m;
    if (!std::regex_search(line, m, re)) return std::nullopt;
    return StrCat(m[1].str(), "/", m[2].str(), " images");
  };
}

ProgressParser ExtractionParser() {
  static const std::regex re(R"(Processed file \[(\d+)/(\d+)\])");
  return ImageCountParser(re);
}

ProgressParser ExhaustiveParser() {
  static const std::regex re(R"(Matching block \[(\d+)/(\d+), (\d+)/(\d+)\])");
  return [](const std::string& line) -> std::optional<std::string> {
    std::smatch m;
    if (!std::regex_search(line, m, re)) return std::nullopt;
    const long a = std::stol(m[1]), b = std::stol(m[2]), c = std::stol(m[3]), d = std::stol(m[4]);
    return StrCat("block ", (a - 1) * d + c, "/", b * d);
  };
}

ProgressParser SequentialParser() {
  static const std::regex re(R"(Matching image \[(\d+)/(\d+)\])");
  return ImageCountParser(re);
}

ProgressParser MapperParser(int num_images) {
  static const std::regex re(R"(Registering image #\d+ \((\d+)\))");
  return [num_images](const std::string& line) -> std::optional<std::string> {
    std::smatch m;
    if (!std::regex_search(line, m, re)) return std::nullopt;
    return StrCat(m[1].str(), "/", num_images, " images registered");
  };
}

}  // namespace perf::sfm_detail
