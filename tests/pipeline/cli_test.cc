// The `perf` executable as a user runs it: help, version, exit codes and messages.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>

#include "tests/test_util.h"

namespace perf {
namespace {

using test::RunCommand;

TEST(Cli, VersionAndHelp) {
  auto r = RunCommand(test::PerfBinary() + " --version");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.output.find("perf 0."), std::string::npos) << r.output;
  // The commit it was built from: 12 hex digits (maybe "-modified"), or "unknown" without git.
  EXPECT_TRUE(std::regex_search(r.output, std::regex(R"(\(commit ([0-9a-f]{12}(-modified)?|unknown)\))")))
      << r.output;
  r = RunCommand(test::PerfBinary() + " --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* sub : {"import", "sfm"}) EXPECT_NE(r.output.find(sub), std::string::npos) << r.output;
  for (const char* sub : {"import", "sfm", "reconstruct", "render", "export", "eval", "run", "view"}) {
    r = RunCommand(test::PerfBinary() + " " + sub + " --help");
    EXPECT_EQ(r.exit_code, 0) << sub;
    // Every command's help ends with the page of the guide that explains its options.
    const std::string page = std::string("docs/commands/") + sub + ".md";
    EXPECT_NE(r.output.find(page), std::string::npos) << r.output;
    EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(PERF_SOURCE_DIR) / page)) << page;
  }
}

TEST(Cli, AFolderThatIsNoWorkspaceGetsNothingWritten) {
  test::TempDir dir;
  for (const char* command : {"reconstruct", "render", "export", "eval"}) {
    const auto r = RunCommand(test::PerfBinary() + " " + command + " " + dir.path().string());
    EXPECT_EQ(r.exit_code, 3) << command << ": " << r.output;
    EXPECT_NE(r.output.find("scene.json"), std::string::npos) << command << ": " << r.output;
    EXPECT_TRUE(std::filesystem::is_empty(dir.path())) << command << " wrote into a folder that is no workspace";
  }
}

TEST(Cli, NoSubcommandIsAnError) {
  const auto r = RunCommand(test::PerfBinary());
  EXPECT_NE(r.exit_code, 0);
}

TEST(Cli, BadInputGivesExitCode2AndNamesTheFile) {
  test::TempDir dir;
  std::filesystem::create_directories(dir / "sparse");
  std::ofstream(dir / "sparse" / "cameras.bin") << "xx";
  auto r = RunCommand(test::PerfBinary() + " import --colmap " + (dir / "sparse").string() + " --images " +
                      dir.path().string() + " -w " + (dir / "ws").string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("error: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("images.bin"), std::string::npos) << r.output;  // which file is missing

  r = RunCommand(test::PerfBinary() + " import --nerf x.json --colmap y -w " + (dir / "ws").string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--colmap/--nerf"), std::string::npos) << r.output;

  r = RunCommand(test::PerfBinary() + " import --nerf x.json --background pink -w " + (dir / "ws").string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--background = pink"), std::string::npos) << r.output;
}

// A value that is not a number, a negative one that once meant "the default", or a weight too
// large to square is refused by every command that takes it, naming the option, before any work
// (so a workspace that does not exist does not matter).
TEST(Cli, BadOptionValuesAreNamedOnEveryCommand) {
  test::TempDir dir;
  const std::string ws = (dir / "ws").string();
  for (const std::string& command : {"reconstruct " + ws, "render " + ws, "export " + ws, "eval " + ws,
                                    "run --nerf x.json -w " + ws}) {
    const auto help = RunCommand(test::PerfBinary() + " " + command.substr(0, command.find(' ')) + " --help");
    for (const std::string option : {"--min-box-opacity nan", "--sh-degree -1", "--sparse-min-opacity nan",
                                     "--smooth-grid -7", "--pose-prior 1e308", "--exposure-prior 1e308",
                                     "--cost-tolerance nan", "--mask-threshold nan", "--iso nan"}) {
      if (help.output.find(option.substr(0, option.find(' ')) + " ") == std::string::npos) continue;  // not its option
      const auto r = RunCommand(test::PerfBinary() + " " + command + " " + option);
      EXPECT_EQ(r.exit_code, 2) << command << " " << option << ": " << r.output;
      EXPECT_NE(r.output.find(option.substr(0, option.find(' '))), std::string::npos) << command << ": " << r.output;
    }
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "ws"));
}

TEST(Cli, MissingFileGivesExitCode3) {
  test::TempDir dir;
  const auto r = RunCommand(test::PerfBinary() + " import --nerf " + (dir / "none.json").string() + " -w " +
                            (dir / "ws").string());
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("none.json"), std::string::npos) << r.output;
}

TEST(Cli, ImportsTheShippedExample) {
  const std::filesystem::path example = std::filesystem::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini";
  ASSERT_TRUE(std::filesystem::exists(example / "sparse" / "0")) << example;
  test::TempDir dir;
  const auto r = RunCommand(test::PerfBinary() + " import -q --colmap " + (example / "sparse" / "0").string() +
                            " -w " + (dir / "ws").string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir / "ws" / "scene.json"));
}

}  // namespace
}  // namespace perf
