#include "common/subprocess.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <optional>

#include "common/errors.h"
#include "common/unique_fd.h"

extern char** environ;

namespace fs = std::filesystem;

namespace perf {
namespace {

// Owns a spawned child, the leader of its own process group, until it has been reaped, so an
// exception while reading its output never leaves a stray process running; the child's own
// children (a tool's helpers, a shell's commands) are in its group and end with it.
class ChildGuard {
 public:
  explicit ChildGuard(pid_t pid) : pid_(pid) {}
  ChildGuard(const ChildGuard&) = delete;
  ChildGuard& operator=(const ChildGuard&) = delete;
  ~ChildGuard() {
    if (pid_ <= 0 || reaped_status_) return;  // (a reaped pid may already be another process's)
    ::kill(-pid_, SIGTERM);
    int status = 0;
    while (::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
    ::kill(-pid_, SIGKILL);  // what of the group outlived its leader
  }
  // Ends a child that has gone quiet, with its process group: SIGTERM, and SIGKILL to whatever of
  // the group still runs once the child ended or `grace` seconds passed. Does not reap it (Wait does).
  void Stop(double grace) {
    ::kill(-pid_, SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(grace);
    while (std::chrono::steady_clock::now() < deadline) {
      int status = 0;
      const pid_t r = ::waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {  // ended: keep its status for Wait
        reaped_status_ = status;
        break;
      }
      if (r < 0 && errno != EINTR) break;
      ::usleep(20000);
    }
    // The group keeps its id while any member lives, so this reaches only the child's own.
    ::kill(-pid_, SIGKILL);
  }
  // Whether the child has ended (its status kept for Wait); then ends what of its group is left,
  // which may hold the output pipe open for ever.
  bool Ended() {
    if (reaped_status_) return true;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) != pid_) return false;
    reaped_status_ = status;
    ::kill(-pid_, SIGKILL);
    return true;
  }
  // Waits for the child; returns its wait status.
  int Wait(const fs::path& program) {
    if (reaped_status_) {
      pid_ = -1;
      return *reaped_status_;
    }
    int status = 0;
    while (::waitpid(pid_, &status, 0) < 0) {
      if (errno != EINTR) throw IoError(program.string(), StrCat("waitpid failed: ", std::strerror(errno)));
    }
    pid_ = -1;
    return status;
  }

 private:
  pid_t pid_;
  std::optional<int> reaped_status_;
};

std::string ShellQuote(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                        "0123456789_-./=:,+") == std::string::npos) {
    return s;
  }
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

bool IsExecutableFile(const fs::path& path) {
  std::error_code ec;
  return fs::is_regular_file(path, ec) && ::access(path.c_str(), X_OK) == 0;
}

// This process's environment with `overrides` replacing same-named entries.
std::vector<std::string> Environment(const std::vector<std::string>& overrides) {
  std::vector<std::string> env;
  for (char** e = environ; e && *e; ++e) {
    const std::string_view entry(*e);
    bool replaced = false;
    for (const std::string& o : overrides) {
      const size_t eq = o.find('=');
      replaced = replaced || (eq != std::string::npos && entry.substr(0, eq + 1) == std::string_view(o).substr(0, eq + 1));
    }
    if (!replaced) env.emplace_back(entry);
  }
  env.insert(env.end(), overrides.begin(), overrides.end());
  return env;
}

std::vector<char*> Pointers(std::vector<std::string>& strings) {
  std::vector<char*> out;
  for (std::string& s : strings) out.push_back(s.data());
  out.push_back(nullptr);
  return out;
}

}  // namespace

std::string CommandLine(const fs::path& program, const std::vector<std::string>& args) {
  std::string line = ShellQuote(program.string());
  for (const std::string& a : args) line += ' ' + ShellQuote(a);
  return line;
}

fs::path FindExecutable(const std::string& binary, const std::string& hint) {
  if (binary.find('/') != std::string::npos) {
    if (!IsExecutableFile(binary)) throw IoError(binary, "the program does not exist or is not executable", hint);
    return binary;
  }
  const char* path_env = std::getenv("PATH");
  const std::string path_list = path_env ? path_env : "";
  size_t begin = 0;
  while (begin <= path_list.size()) {
    size_t end = path_list.find(':', begin);
    if (end == std::string::npos) end = path_list.size();
    // An empty PATH entry means the current directory (POSIX).
    const fs::path dir = end == begin ? fs::path(".") : fs::path(path_list.substr(begin, end - begin));
    if (IsExecutableFile(dir / binary)) return dir / binary;
    begin = end + 1;
  }
  throw IoError(binary, "`" + binary + "` was not found on PATH", hint);
}

ProcessResult RunProcess(const fs::path& program, const std::vector<std::string>& args,
                         const std::vector<std::string>& env,
                         const std::function<void(std::string_view)>& on_output, double idle_timeout_seconds) {
  std::vector<std::string> argv_storage{program.string()};
  argv_storage.insert(argv_storage.end(), args.begin(), args.end());
  std::vector<std::string> env_storage = Environment(env);
  std::vector<char*> argv = Pointers(argv_storage), envp = Pointers(env_storage);

  // O_CLOEXEC: children spawned concurrently by other threads must not inherit our pipe, or
  // we would never see end-of-file. The dup2 onto 1 and 2 below clears the flag in the child.
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) {
    throw IoError(program.string(), StrCat("cannot create a pipe: ", std::strerror(errno)));
  }
  UniqueFd read_end(fds[0]), write_end(fds[1]);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, write_end.get(), STDOUT_FILENO);
  posix_spawn_file_actions_adddup2(&actions, write_end.get(), STDERR_FILENO);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  // Its own process group (pgid = its pid), so that a stop reaches everything it starts.
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP);
  posix_spawnattr_setpgroup(&attr, 0);
  pid_t pid = -1;
  const int spawn_error = ::posix_spawn(&pid, program.c_str(), &actions, &attr, argv.data(), envp.data());
  posix_spawnattr_destroy(&attr);
  posix_spawn_file_actions_destroy(&actions);
  if (spawn_error != 0) {
    throw IoError(program.string(), StrCat("cannot start the program: ", std::strerror(spawn_error)),
                  "check that it is an executable");
  }
  ChildGuard child(pid);
  write_end.Close();  // so read() sees end-of-file when the child exits

  char buf[4096];
  bool idle = false;
  using Clock = std::chrono::steady_clock;
  auto last_output = Clock::now();
  while (true) {
    if (idle_timeout_seconds > 0) {
      const double quiet = std::chrono::duration<double>(Clock::now() - last_output).count();
      if (quiet >= idle_timeout_seconds) {
        idle = true;
        child.Stop(kIdleKillGraceSeconds);
        break;
      }
    }
    // Woken at least every kHeartbeatSeconds: on_output gets an empty chunk, so that a caller can
    // stop a quiet child (Ctrl-C) by throwing.
    pollfd p{read_end.get(), POLLIN, 0};
    double wait = kHeartbeatSeconds;
    if (idle_timeout_seconds > 0) {
      wait = std::min(wait, idle_timeout_seconds - std::chrono::duration<double>(Clock::now() - last_output).count());
    }
    const int ready = ::poll(&p, 1, std::max(1, static_cast<int>(std::ceil(wait * 1000))));
    if (ready < 0 && errno != EINTR) {
      throw IoError(program.string(), StrCat("cannot wait for the program's output: ", std::strerror(errno)));
    }
    if (ready == 0) {
      on_output({});
      if (child.Ended()) break;  // whatever still holds the pipe was its, and is ended
    }
    if (ready <= 0) continue;
    const ssize_t n = ::read(read_end.get(), buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw IoError(program.string(), StrCat("cannot read the program's output: ", std::strerror(errno)));
    if (n == 0) break;
    last_output = Clock::now();
    on_output(std::string_view(buf, static_cast<size_t>(n)));
  }
  const int status = child.Wait(program);
  ProcessResult result;
  result.idle = idle;
  if (WIFSIGNALED(status)) {
    result.signal = WTERMSIG(status);
  } else {
    result.exit_code = WEXITSTATUS(status);
  }
  return result;
}

}  // namespace perf
