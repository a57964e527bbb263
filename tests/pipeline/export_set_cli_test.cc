// An export's files reach the workspace as one set (export/export_set.h): a write that fails part
// way leaves the old set and its export.json; a mesh that comes out empty takes the old texture
// with it; export.json lists exactly the export's files on disk, whatever was exported before.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "common/atomic_file.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

std::string Perf(const std::string& args) { return "timeout 300 " + test::PerfBinary() + " " + args; }

// The export's files as they are on disk (the groups export_set.h names), relative, with their bytes.
std::map<std::string, std::string> ExportFiles(const fs::path& ws) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(ws)) {
    const fs::path rel = e.path().lexically_relative(ws);
    const std::string first = rel.begin()->string();
    const bool exported = first == "masks" || first == "foreground" || first == "renders" || first == "volume.vdb" ||
                          first == "export.json" || (rel.parent_path().empty() && rel.stem() == "mesh");
    if (e.is_regular_file() && exported) files[rel.generic_string()] = ReadFileToString(e.path());
  }
  return files;
}

// export.json names every export file on disk and no other.
void ExpectManifestDescribesDisk(const fs::path& ws) {
  const nlohmann::json manifest = nlohmann::json::parse(ReadFileToString(ws / "export.json"));
  std::set<std::string> listed{"export.json"}, on_disk;
  for (const auto& f : manifest["files"]) listed.insert(f.get<std::string>());
  for (const auto& [rel, bytes] : ExportFiles(ws)) on_disk.insert(rel);
  EXPECT_TRUE(listed == on_disk) << manifest["files"].dump();
}

class ExportSetCli : public ::testing::Test {
 protected:
  void SetUp() override {
    test::MakeSyntheticWorkspace(dir_.path(), ws_);
    Reconstruct(4);
  }
  void Reconstruct(int iterations) {
    const auto r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 16 --iterations " +
                                   std::to_string(iterations)));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  test::CommandResult Export(const std::string& more = "") {
    return RunCommand(Perf("export -q " + ws_.string() + " --orbit-frames 2" + more));
  }
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

// The mesh's OBJ cannot be written (a write failure injected by the test hook, as a full disk
// would fail it after the volume and the PLY were written): the old volume, PLY, OBJ, GLB,
// texture and export.json all stay, and nothing new is mixed in.
TEST_F(ExportSetCli, AFailedExportLeavesTheOldSet) {
  ASSERT_EQ(Export().exit_code, 0);
  const auto before = ExportFiles(ws_);
  ASSERT_TRUE(before.count("mesh.png") && before.count("volume.vdb") && before.count("mesh.obj"));
  Reconstruct(8);  // another fit: every file of a new export differs
  const auto r = RunCommand("PERF_TEST_FAIL_WRITE=mesh.obj " + Perf("export -q " + ws_.string() + " --orbit-frames 2"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("mesh.obj"), std::string::npos) << r.output;
  EXPECT_TRUE(ExportFiles(ws_) == before) << "the old set changed";
  EXPECT_FALSE(fs::exists(ws_ / ".perf" / "export")) << "the failed export's staged files stayed";
  ASSERT_EQ(Export().exit_code, 0);  // and the next export goes through
  EXPECT_FALSE(ExportFiles(ws_)["volume.vdb"] == before.at("volume.vdb"));
  ExpectManifestDescribesDisk(ws_);
}

// A mesh that comes out empty has no texture: the old mesh.png and mesh.mtl go with the old mesh
// (perf view would show them); an export without the mesh keeps the old one, and lists it.
TEST_F(ExportSetCli, AnEmptyMeshLeavesNoStaleTexture) {
  ASSERT_EQ(Export().exit_code, 0);
  ASSERT_TRUE(fs::exists(ws_ / "mesh.png"));
  const auto r = Export(" --iso 0.9999");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json manifest = nlohmann::json::parse(ReadFileToString(ws_ / "export.json"));
  ASSERT_EQ(manifest["mesh"]["triangles"], 0) << "the test needs an empty mesh";
  EXPECT_FALSE(fs::exists(ws_ / "mesh.png"));
  EXPECT_FALSE(fs::exists(ws_ / "mesh.mtl"));
  EXPECT_TRUE(fs::exists(ws_ / "mesh.obj"));
  ExpectManifestDescribesDisk(ws_);
  ASSERT_EQ(Export(" --no-mesh --no-volume").exit_code, 0);
  EXPECT_TRUE(fs::exists(ws_ / "mesh.ply"));
  EXPECT_TRUE(fs::exists(ws_ / "volume.vdb"));
  ExpectManifestDescribesDisk(ws_);
}

}  // namespace
}  // namespace perf
