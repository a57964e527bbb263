// RunProcess (common/subprocess.h): output passed through, exit codes and signals, and a child
// that goes quiet stopped after the idle limit.
#include "common/subprocess.h"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>

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
// Whether process `pid` still runs (a zombie waiting for its reaper does not).
bool Running(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return false;
  const size_t paren = line.rfind(')');
  return paren != std::string::npos && paren + 2 < line.size() && line[paren + 2] != 'Z';
}

// A stuck child is ended with everything it started (its process group): a grandchild that
// holds the output pipe or keeps working would otherwise outlive perf.
TEST(Subprocess, AStuckChildIsEndedWithItsProcessGroup) {
  const std::string pid_file = ::testing::TempDir() + "/perf_grandchild_" + std::to_string(::getpid());
  const Ran ran = RunShell("sleep 60 & echo $! > " + pid_file + "; echo started; sleep 60", 0.5);
  EXPECT_TRUE(ran.result.idle);
  EXPECT_LT(ran.seconds, 10);
  std::ifstream in(pid_file);
  pid_t grandchild = 0;
  ASSERT_TRUE(in >> grandchild) << ran.out;
  for (int i = 0; i < 100 && Running(grandchild); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_FALSE(Running(grandchild)) << "the grandchild " << grandchild << " still runs";
  if (Running(grandchild)) ::kill(grandchild, SIGKILL);
  std::remove(pid_file.c_str());
}

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
