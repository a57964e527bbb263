// Helpers shared by the tests: a self-deleting temporary folder, the shared data location,
// and running the `perf` binary.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <string>
#include <thread>

namespace perf::test {

class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() /
            ("perf_test_" + std::to_string(::getpid()) + "_" + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& s) const { return path_ / s; }

 private:
  std::filesystem::path path_;
};

// ../shared/data beside the checkout (CI has it); empty if absent.
inline std::filesystem::path SharedData(const std::string& sub) {
  const std::filesystem::path p = std::filesystem::path(PERF_SHARED_DATA_DIR) / sub;
  return std::filesystem::exists(p) ? p : std::filesystem::path();
}

#define PERF_REQUIRE_DATA(var, sub)                                                         \
  const std::filesystem::path var = ::perf::test::SharedData(sub);                          \
  if (var.empty()) GTEST_SKIP() << "shared data " << sub << " not found beside the checkout (" \
                                << PERF_SHARED_DATA_DIR << "); skipping"

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

// Runs a shell command line, capturing its output.
inline CommandResult RunCommand(const std::string& cmd) {
  CommandResult r;
  FILE* pipe = ::popen((cmd + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int status = ::pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// Every regular file under `dir` (recursively) with its bytes: a snapshot to compare after a command.
inline std::map<std::filesystem::path, std::string> FilesUnder(const std::filesystem::path& dir) {
  std::map<std::filesystem::path, std::string> files;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    std::ifstream in(e.path(), std::ios::binary);
    files[e.path()] = std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  return files;
}

// The perf binary under test: this build's, or PERF_TEST_BINARY's (e.g. an older build, to check
// that a new test fails there).
inline std::string PerfBinary() {
  const char* other = std::getenv("PERF_TEST_BINARY");
  return other != nullptr && *other != 0 ? std::string(other) : std::string(PERF_BINARY_DIR) + "/perf";
}

// Starts `command` (a shell command line, its output discarded) in the background; stops it with
// `sig` `delay_ms` after `sign` exists (or after 5 minutes without it), and returns its wait status.
inline int StopWhenExists(const std::string& command, const std::filesystem::path& sign, int sig,
                          int delay_ms = 300) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl("/bin/sh", "sh", "-c", ("exec " + command + " > /dev/null 2>&1").c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(5);
  while (!std::filesystem::exists(sign) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
  ::kill(pid, sig);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return status;
}

}  // namespace perf::test
