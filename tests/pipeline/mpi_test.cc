// `mpirun -np 2 perf reconstruct` (issue 17) against one process on lego 50x50: the same cost at
// every iteration and the same held-out PSNR; and a rank that fails (bad photo in its share, or
// killed) ends every rank with an error instead of leaving the others waiting. Label `mpi`: skips
// with a message where mpirun or an MPI build is missing, or without ../shared/data.
// Built twice: mpi_test (the CPU cases) and, with PERF_MPI_TEST_GPU, mpi_gpu_test (label gpu: two
// GPU ranks summing with NCCL against one GPU).
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>

#include "common/errors.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Open MPI refuses to start as root (CI's containers) unless told it may.
const char* const kMpirun =
    "env OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 mpirun";

#define PERF_REQUIRE_MPI()                                                                               \
  if (!PERF_TEST_HAVE_MPI) GTEST_SKIP() << "perf was built without MPI (libopenmpi-dev missing); skipping"; \
  if (test::RunCommand("command -v mpirun").exit_code != 0) GTEST_SKIP() << "mpirun not found; skipping"

std::vector<json> LogLines(const fs::path& ws, const std::string& event) {
  std::vector<json> out;
  std::ifstream in(ws / "recon" / "log.jsonl");
  for (std::string line; std::getline(in, line);) {
    json j = json::parse(line);
    if (j.value("event", "") == event) out.push_back(std::move(j));
  }
  return out;
}

class MpiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    PERF_REQUIRE_MPI();
    PERF_REQUIRE_DATA(lego, "lego");
    const test::CommandResult r = test::RunCommand(StrCat(test::PerfBinary(), " import --nerf ", lego / "transforms_train.json",
                                                          " -w ", dir_ / "ws", " --downscale 16 -q"));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  // A copy of the imported workspace.
  fs::path Workspace(const std::string& name) {
    fs::copy(dir_ / "ws", dir_ / name, fs::copy_options::recursive);
    return dir_ / name;
  }
  std::string Reconstruct(const fs::path& ws, int threads, const std::string& device = "cpu") const {
    return StrCat(test::PerfBinary(), " reconstruct ", ws, " --device ", device, " --levels 2 --iterations 4 -q -j ",
                  threads);
  }
  // One process with `threads` threads, then 2 ranks of one thread each, on `device`.
  void CompareTwoRanksWithOneProcess(const std::string& device, int threads);
  test::TempDir dir_;
};

void MpiTest::CompareTwoRanksWithOneProcess(const std::string& device, int threads) {
  const fs::path one = Workspace("one"), two = Workspace("two");
  test::CommandResult r = test::RunCommand(Reconstruct(one, threads, device));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = test::RunCommand(StrCat("timeout 300 ", kMpirun, " -np 2 ", Reconstruct(two, 1, device)));
  ASSERT_EQ(r.exit_code, 0) << r.output;

  const std::vector<json> a = LogLines(one, "iteration"), b = LogLines(two, "iteration");
  ASSERT_EQ(a.size(), 8u);
  ASSERT_EQ(b.size(), a.size()) << "rank 0 alone writes the log, once";
  for (size_t i = 0; i < a.size(); ++i) {
    const double ca = a[i]["cost"], cb = b[i]["cost"];
    EXPECT_NEAR(cb, ca, 1e-4 * ca) << "iteration " << i << " (float sums in another order only)";
    EXPECT_EQ(b[i]["rays"], a[i]["rays"]) << "each level's rays over both ranks";
    EXPECT_EQ(b[i]["ranks"], 2);
    EXPECT_GT(b[i]["summed_bytes"].get<int64_t>(), 0);
  }
  for (const json& level : LogLines(two, "level")) {
    ASSERT_EQ(level["rank_pass_seconds"].size(), 2u) << level.dump();
    for (const json& s : level["rank_pass_seconds"]) EXPECT_GT(s.get<double>(), 0.0) << "every rank ran its passes";
    EXPECT_EQ(level["rank_sum_seconds"].size(), 2u);
  }
  const json ja = json::parse(std::ifstream(one / "recon" / "recon.json"));
  const json jb = json::parse(std::ifstream(two / "recon" / "recon.json"));
  EXPECT_EQ(jb["ranks"], 2);
  EXPECT_EQ(ja["ranks"], 1);
  const double pa = ja["test_psnr"], pb = jb["test_psnr"];
  std::printf("lego 50x50 on %s, 4 + 4 GN: held-out PSNR %.4f dB (1 process) and %.4f dB (2 ranks); %lld bytes "
              "summed in the last iteration; %s\n",
              device.c_str(), pa, pb, static_cast<long long>(b.back()["summed_bytes"].get<int64_t>()),
              jb["backend"].get<std::string>().c_str());
  EXPECT_GT(pa, 20.0);
  EXPECT_NEAR(pb, pa, 0.05);
  EXPECT_TRUE(fs::exists(two / "recon" / "level_1.perfvol"));
}

#if !PERF_MPI_TEST_GPU
TEST_F(MpiTest, TwoRanksFitWhatOneProcessFits) { CompareTwoRanksWithOneProcess("cpu", 2); }

// perf run under mpirun: rank 0 imports and exports, both ranks fit; one summary, one lock.
TEST_F(MpiTest, TheWholePipelineOnTwoRanks) {
  PERF_REQUIRE_DATA(lego, "lego");
  const fs::path ws = dir_ / "run";
  const test::CommandResult r = test::RunCommand(StrCat("timeout 300 ", kMpirun, " -np 2 ", test::PerfBinary(),
                                                        " run --nerf ", lego / "transforms_train.json", " -w ", ws,
                                                        " --max-size 50 --levels 1 --iterations 2 --device cpu -j 1"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json recon = json::parse(std::ifstream(ws / "recon" / "recon.json"));
  EXPECT_EQ(recon["ranks"], 2);
  EXPECT_GT(recon["test_psnr"].get<double>(), 15.0);
  EXPECT_TRUE(fs::exists(ws / "volume.vdb"));
  EXPECT_TRUE(fs::exists(ws / "report.html"));
  size_t summaries = 0;
  for (size_t at = r.output.find("Done in "); at != std::string::npos; at = r.output.find("Done in ", at + 1)) ++summaries;
  EXPECT_EQ(summaries, 1u) << "rank 0 alone reports: " << r.output;
}



TEST_F(MpiTest, ARankThatCannotReadItsPhotoEndsEveryRank) {
  const fs::path ws = Workspace("bad");
  // The last training photo belongs to the last rank's share.
  const json scene = json::parse(std::ifstream(ws / "scene.json"));
  std::string last;
  for (const json& im : scene["images"]) {
    if (im["split"] == "train") last = im["path"];
  }
  ASSERT_FALSE(last.empty());
  std::ofstream(ws / last) << "not an image";
  const auto t0 = std::chrono::steady_clock::now();
  const test::CommandResult r = test::RunCommand(StrCat("timeout 120 ", kMpirun, " -np 2 ", Reconstruct(ws, 1)));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.exit_code, 2) << r.output;  // bad input, from the failing rank (124: timeout, a hang)
  EXPECT_NE(r.output.find("error (rank 1 of 2)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(last), std::string::npos) << "the message names the photo: " << r.output;
  EXPECT_LT(seconds, 60.0);
  EXPECT_FALSE(fs::exists(ws / "recon" / "level_0.perfvol"));
}

TEST_F(MpiTest, AKilledRankEndsTheJob) {
  const fs::path ws = Workspace("killed");
  // mpirun in the background; once rank 0 logs an iteration, SIGKILL rank 1.
  const std::string script = StrCat(
      "(timeout 300 ", kMpirun, " -np 2 ", Reconstruct(ws, 1), " > ", dir_ / "mpirun.log", " 2>&1; echo $? > ",
      dir_ / "mpirun.rc", ") & "
      "for i in $(seq 600); do [ -s ", ws / "recon" / "log.jsonl", " ] && break; sleep 0.1; done; "
      "for p in $(pgrep -f 'perf reconstruct ", ws.string(), "'); do "
      "  if tr '\\0' '\\n' < /proc/$p/environ 2>/dev/null | grep -qx OMPI_COMM_WORLD_RANK=1; then kill -9 $p; echo killed $p; fi; "
      "done; wait");
  const auto t0 = std::chrono::steady_clock::now();
  const test::CommandResult r = test::RunCommand(script);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_NE(r.output.find("killed"), std::string::npos) << "rank 1 was not found: " << r.output;
  std::ifstream rc_file(dir_ / "mpirun.rc");
  int rc = -1;
  rc_file >> rc;
  std::ifstream log_file(dir_ / "mpirun.log");
  const std::string log((std::istreambuf_iterator<char>(log_file)), std::istreambuf_iterator<char>());
  EXPECT_NE(rc, 0) << log;
  EXPECT_NE(rc, 124) << "mpirun hung until the timeout: " << log;
  EXPECT_LT(seconds, 200.0);
  // What rank 0 wrote is whole: no temporary files left beside the checkpoints.
  for (const auto& e : fs::directory_iterator(ws / "recon")) {
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
  }
  // And the job resumes on 2 ranks from what was written (from the start if no level was done).
  const test::CommandResult resumed =
      test::RunCommand(StrCat("timeout 300 ", kMpirun, " -np 2 ", Reconstruct(ws, 1), " --resume"));
  EXPECT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_TRUE(fs::exists(ws / "recon" / "level_1.perfvol"));
  EXPECT_EQ(json::parse(std::ifstream(ws / "recon" / "recon.json"))["ranks"], 2);
}

#else  // mpi_gpu_test: the same fixture, label gpu

// Two GPUs, one per rank, summing with NCCL where the build has it (gpu: written, run where a
// machine has two GPUs and MPI; skips elsewhere).
class MpiGpuTest : public MpiTest {
 protected:
  void SetUp() override {
    const test::CommandResult gpus = test::RunCommand("nvidia-smi -L | grep -c '^GPU'");
    if (gpus.exit_code != 0 || std::atoi(gpus.output.c_str()) < 2) GTEST_SKIP() << "fewer than 2 GPUs; skipping";
    MpiTest::SetUp();
  }
};

TEST_F(MpiGpuTest, TwoGpuRanksFitWhatOneGpuFits) { CompareTwoRanksWithOneProcess("cuda", 1); }

#endif  // PERF_MPI_TEST_GPU

}  // namespace
}  // namespace perf
