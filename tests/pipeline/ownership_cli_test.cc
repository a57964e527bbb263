// The third reliability pass on the command line: PERF replaces, appends to or removes only files
// it made itself (common/owned_files.h), whatever a list of inputs says or does not say. Each case
// here changed a user's file before: a photo named like a temporary, renders over photos once
// inputs.json was gone, --log-json onto an input, logs that follow a planted link.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

std::string Perf(const std::string& args) { return "timeout 120 " + test::PerfBinary() + " " + args; }

void ExpectRefusedNaming(const test::CommandResult& r, const fs::path& file) {
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find(file.filename().string()), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("PERF did not write"), std::string::npos) << r.output;
}

class OwnershipCli : public ::testing::Test {
 protected:
  void SetUp() override { test::MakeSyntheticWorkspace(dir_.path(), ws_); }
  test::CommandResult Reconstruct(const std::string& more = "") {
    return RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 8 --iterations 1" + more));
  }
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

// A COLMAP project used as the workspace: its photo folder is WORKSPACE/images, where a photo
// named like a temporary of a dead process was swept away by the first import.
TEST(OwnershipCliPlain, APhotoNamedLikeATemporaryInALaidOverWorkspaceStays) {
  test::TempDir dir;
  const fs::path project = dir / "project";
  fs::copy(fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini", project, fs::copy_options::recursive);
  const fs::path photo = project / "images" / "holiday.tmp999999-7.JPG";
  fs::copy_file(project / "images" / "DSCF5608.JPG", photo);
  const std::string before = ReadFileToString(photo);
  const auto r = RunCommand(Perf("import -q --colmap " + (project / "sparse" / "0").string() + " --images " +
                                 (project / "images").string() + " --workspace " + project.string()));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(photo)) << "a user's photo was deleted";
  EXPECT_EQ(ReadFileToString(photo), before);
}

// With inputs.json gone (an older workspace, or one a user tidied), renders still never land on
// a file PERF did not write.
TEST_F(OwnershipCli, RenderIntoThePhotosWithoutAnInputRecordIsRefused) {
  ASSERT_EQ(Reconstruct().exit_code, 0);
  fs::remove(ws_ / "inputs.json");
  const auto photos = test::FilesUnder(dir_ / "images");
  const auto r = RunCommand(Perf("render -q " + ws_.string() + " --split all -o " + (dir_ / "images").string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find((dir_ / "images").string()), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("choose another path"), std::string::npos) << r.output;
  EXPECT_TRUE(test::FilesUnder(dir_ / "images") == photos) << "a photo was written over";
  // A render into a new folder works, and again over its own renders.
  for (int k = 0; k < 2; ++k) {
    const auto again = RunCommand(Perf("render -q " + ws_.string() + " -o " + (dir_ / "renders").string()));
    EXPECT_EQ(again.exit_code, 0) << again.output;
  }
}

// --log-json appends only to a log PERF started: not to a photo, not to the json being imported.
TEST_F(OwnershipCli, LogJsonOntoAnInputIsRefused) {
  const fs::path photo = dir_ / "images" / "view1.png";
  ASSERT_TRUE(fs::exists(photo));
  for (const fs::path& input : {photo, dir_ / "transforms.json"}) {
    const std::string before = ReadFileToString(input);
    const auto r = RunCommand(Perf("run --log-level quiet --nerf " + (dir_ / "transforms.json").string() +
                                   " --workspace " + (dir_ / "ws_log").string() +
                                   " --levels 1 --iterations 1 --log-json " + input.string()));
    ExpectRefusedNaming(r, input);
    EXPECT_EQ(ReadFileToString(input), before) << input;
  }
  EXPECT_FALSE(fs::exists(dir_ / "ws_log")) << "a refused first run left its workspace";
}

// recon/log.jsonl replaced by a link to a file outside the workspace: --resume does not append
// through it.
TEST_F(OwnershipCli, APlantedLogLinkIsNotFollowed) {
  ASSERT_EQ(Reconstruct().exit_code, 0);
  const fs::path log = ws_ / "recon" / "log.jsonl", victim = dir_ / "victim.txt";
  std::ofstream(victim) << "someone else's file\n";
  fs::remove(log);
  fs::create_symlink(victim, log);
  const auto r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 2 --start-resolution 8 --iterations 1 --resume"));
  ExpectRefusedNaming(r, log);
  EXPECT_EQ(ReadFileToString(victim), "someone else's file\n");
}

// colmap/colmap.log likewise: a fake colmap that fails at once is enough to open the log.
TEST_F(OwnershipCli, APlantedColmapLogLinkIsNotFollowed) {
  const fs::path fake = dir_ / "colmap.sh", ws = dir_ / "ws_sfm", victim = dir_ / "victim.txt";
  std::ofstream(fake) << "#!/bin/sh\necho failing\nexit 1\n";
  fs::permissions(fake, fs::perms::owner_all);
  fs::create_directories(ws);
  const std::string sfm = Perf("sfm -q --images " + (dir_ / "images").string() + " --workspace " + ws.string() +
                               " --colmap-binary " + fake.string());
  auto r = RunCommand(sfm);
  ASSERT_NE(r.exit_code, 0) << r.output;
  const fs::path log = ws / "colmap" / "colmap.log";
  ASSERT_TRUE(fs::exists(log)) << r.output;
  std::ofstream(victim) << "someone else's file\n";
  fs::remove(log);
  fs::create_symlink(victim, log);
  r = RunCommand(sfm);
  ExpectRefusedNaming(r, log);
  EXPECT_EQ(ReadFileToString(victim), "someone else's file\n");
}

// A workspace of an older PERF (no record of what it wrote) is not written over: its outputs are
// not PERF's as far as this one can tell.
TEST_F(OwnershipCli, AnOutputPerfCannotShowItWroteIsRefused) {
  ASSERT_EQ(Reconstruct().exit_code, 0);
  const fs::path report = ws_ / "report.json";
  std::ofstream(report) << "a user's notes\n";
  const auto r = RunCommand(Perf("eval -q " + ws_.string()));
  ExpectRefusedNaming(r, report);
  EXPECT_EQ(ReadFileToString(report), "a user's notes\n");
}

// A folder of the workspace replaced by a link to a folder elsewhere (a user's photos, another
// disk): nothing is written through it. Before, a re-import wrote its PNGs into the user's folder.
TEST_F(OwnershipCli, NothingIsWrittenThroughALinkedFolder) {
  const fs::path elsewhere = dir_ / "elsewhere";
  fs::create_directories(elsewhere);
  std::ofstream(elsewhere / "notes.txt") << "a user's notes\n";
  fs::create_symlink(elsewhere, ws_ / "recon");
  const auto r = Reconstruct();
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("recon"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("symbolic link"), std::string::npos) << r.output;
  EXPECT_EQ(test::FilesUnder(elsewhere).size(), 1u) << "files were written outside the workspace";
  EXPECT_EQ(ReadFileToString(elsewhere / "notes.txt"), "a user's notes\n");
}

}  // namespace
}  // namespace perf
