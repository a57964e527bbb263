// RunProcess (common/subprocess.h): output passed through, exit codes and signals, and a child
// that goes quiet stopped after the idle limit.
#include "common/subprocess.h"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <string>

namespace perf {
namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

ProcessResult RunShell(const std::string& script, std::string* output, double idle_timeout = 0) {
  return RunProcess("/bin/sh", {"-c", script}, {}, [&](std::string_view chunk) { output->append(chunk); },
                    idle_timeout);
}

TEST(Subprocess, PassesOutputAndExitCode) {
  std::string out;
  const ProcessResult r = RunShell("echo hello; echo oops >&2; exit 3", &out);
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_EQ(r.signal, 0);
  EXPECT_FALSE(r.idle);
  EXPECT_NE(out.find("hello"), std::string::npos) << out;
  EXPECT_NE(out.find("oops"), std::string::npos) << out;
}

TEST(Subprocess, AQuietChildIsStoppedAfterTheIdleLimit) {
  std::string out;
  const auto t0 = std::chrono::steady_clock::now();
  const ProcessResult r = RunShell("echo started; exec sleep 30", &out, 0.5);
  EXPECT_TRUE(r.idle);
  EXPECT_EQ(r.signal, SIGTERM);
  EXPECT_LT(Seconds(t0), 5.0);
  EXPECT_NE(out.find("started"), std::string::npos) << out;
}

TEST(Subprocess, AChildThatIgnoresSigtermIsKilled) {
  std::string out;
  const auto t0 = std::chrono::steady_clock::now();
  // The shell ignores TERM and waits on a child that would outlive the test.
  const ProcessResult r = RunShell("trap '' TERM; echo started; sleep 30; echo survived", &out, 0.5);
  EXPECT_TRUE(r.idle);
  EXPECT_EQ(r.signal, SIGKILL);
  EXPECT_LT(Seconds(t0), 0.5 + kIdleKillGraceSeconds + 3);
  EXPECT_EQ(out.find("survived"), std::string::npos) << out;
}

TEST(Subprocess, AChildThatKeepsPrintingRunsPastTheIdleLimit) {
  std::string out;
  const auto t0 = std::chrono::steady_clock::now();
  const ProcessResult r = RunShell("for i in 1 2 3 4 5 6; do echo tick $i; sleep 0.25; done", &out, 0.8);
  EXPECT_FALSE(r.idle);
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_GT(Seconds(t0), 1.2);  // longer than the idle limit in all
  EXPECT_NE(out.find("tick 6"), std::string::npos) << out;
}

}  // namespace
}  // namespace perf
