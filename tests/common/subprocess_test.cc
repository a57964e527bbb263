// RunProcess (common/subprocess.h): output passed through, exit codes and signals, and a child
// that goes quiet stopped after the idle limit.
#include "common/subprocess.h"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <string>

namespace perf {
namespace {

// What a shell script did: its result, everything it printed and how long it took.
struct Ran {
  ProcessResult result;
  std::string out;
  double seconds = 0;
};

Ran RunShell(const std::string& script, double idle_timeout = 0) {
  Ran ran;
  const auto t0 = std::chrono::steady_clock::now();
  ran.result = RunProcess("/bin/sh", {"-c", script}, {}, [&](std::string_view chunk) { ran.out.append(chunk); },
                          idle_timeout);
  ran.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return ran;
}

TEST(Subprocess, PassesOutputAndExitCode) {
  const Ran ran = RunShell("echo hello; echo oops >&2; exit 3");
  EXPECT_EQ(ran.result.exit_code, 3);
  EXPECT_EQ(ran.result.signal, 0);
  EXPECT_FALSE(ran.result.idle);
  EXPECT_NE(ran.out.find("hello"), std::string::npos) << ran.out;
  EXPECT_NE(ran.out.find("oops"), std::string::npos) << ran.out;
}

TEST(Subprocess, AQuietChildIsStoppedAfterTheIdleLimit) {
  const Ran ran = RunShell("echo started; exec sleep 30", 0.5);
  EXPECT_TRUE(ran.result.idle);
  EXPECT_EQ(ran.result.signal, SIGTERM);
  EXPECT_LT(ran.seconds, 5.0);
  EXPECT_NE(ran.out.find("started"), std::string::npos) << ran.out;
}

// The shell ignores TERM and waits on a child that would outlive the test.
TEST(Subprocess, AChildThatIgnoresSigtermIsKilled) {
  const Ran ran = RunShell("trap '' TERM; echo started; sleep 30; echo survived", 0.5);
  EXPECT_TRUE(ran.result.idle);
  EXPECT_EQ(ran.result.signal, SIGKILL);
  EXPECT_LT(ran.seconds, 0.5 + kIdleKillGraceSeconds + 3);
  EXPECT_EQ(ran.out.find("survived"), std::string::npos) << ran.out;
}

TEST(Subprocess, AChildThatKeepsPrintingRunsPastTheIdleLimit) {
  const Ran ran = RunShell("for i in 1 2 3 4 5 6; do echo tick $i; sleep 0.25; done", 0.8);
  EXPECT_FALSE(ran.result.idle);
  EXPECT_EQ(ran.result.exit_code, 0);
  EXPECT_GT(ran.seconds, 1.2);  // longer than the idle limit in all
  EXPECT_NE(ran.out.find("tick 6"), std::string::npos) << ran.out;
}

}  // namespace
}  // namespace perf
