// Running another program (the colmap CLI) without a shell: arguments pass through untouched,
// stdin is /dev/null, stdout and stderr come back through one pipe as they are written, and the
// child is never left running when the caller throws.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace perf {

struct ProcessResult {
  int exit_code = 0;   // valid when signal == 0
  int signal = 0;      // the signal that killed the process, or 0
  bool idle = false;   // stopped by us: it printed nothing for idle_timeout_seconds
};

// Runs `program` with `args` as the leader of a process group of its own; `env` entries
// ("NAME=value") replace or add to this process's environment. `on_output` receives the child's
// output in chunks as it arrives, and an empty chunk every kHeartbeatSeconds of silence; if it
// throws, the child's group gets SIGTERM (then SIGKILL) and the child is reaped before the
// exception propagates. A child that prints nothing for idle_timeout_seconds (> 0; 0: no limit)
// gets SIGTERM with its group, and SIGKILL if it has not ended kIdleKillGraceSeconds later; the
// result says `idle`. Throws IoError when the program cannot be started. The group is not the
// terminal's: a Ctrl-C reaches the child only through the caller (on_output throwing).
inline constexpr double kIdleKillGraceSeconds = 3;
inline constexpr double kHeartbeatSeconds = 0.25;
ProcessResult RunProcess(const std::filesystem::path& program, const std::vector<std::string>& args,
                         const std::vector<std::string>& env,
                         const std::function<void(std::string_view chunk)>& on_output,
                         double idle_timeout_seconds = 0);

// `program args...` as a shell would need it typed, for logs and messages.
std::string CommandLine(const std::filesystem::path& program, const std::vector<std::string>& args);

// `binary` itself when it names a path, else the first executable of that name on PATH; throws
// IoError with `hint` otherwise.
std::filesystem::path FindExecutable(const std::string& binary, const std::string& hint);

}  // namespace perf
