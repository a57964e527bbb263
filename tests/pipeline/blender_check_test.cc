// Blender (Debian's 3.4, background mode) opens PERF's textured mesh as a DCC user would: the OBJ
// and the GLB with their faces, a material whose Base Color is the baked texture, and texture
// coordinates in [0, 1] (tests/export/blender_import.py). Label slow: Blender takes a while to
// start; skipped with a message where it is not installed.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

TEST(BlenderCheck, BlenderOpensTheTexturedObjAndGlb) {
  if (RunCommand("command -v blender").exit_code != 0) {
    GTEST_SKIP() << "blender not found (Debian package blender); skipping the Blender import check";
  }
  test::TempDir dir;
  const fs::path ws = dir / "ws";
  test::MakeSyntheticWorkspace(dir.path(), ws);
  const std::string perf = test::PerfBinary();
  auto r = RunCommand(perf + " reconstruct -q " + ws.string() + " --levels 1 --start-resolution 16 --iterations 4");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunCommand(perf + " export -q " + ws.string() + " --no-masks --no-foreground --no-renders --no-volume");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json mesh = nlohmann::json::parse(ReadFileToString(ws / "export.json"))["mesh"];
  ASSERT_GT(mesh["triangles"].get<int64_t>(), 0) << mesh.dump();

  // PERF_BLENDER_RENDER=path also renders the OBJ there (how docs/mesh_blender.png was made).
  const char* render = std::getenv("PERF_BLENDER_RENDER");
  const fs::path out = dir / "blender.json";
  std::string command = "blender -b --factory-startup --python " + std::string(PERF_SOURCE_DIR) +
                        "/tests/export/blender_import.py -- " + out.string() + " " + ws.string();
  if (render != nullptr) command += std::string(" ") + render;
  r = RunCommand(command);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(out)) << r.output;
  const nlohmann::json seen = nlohmann::json::parse(ReadFileToString(out));
  for (const char* format : {"obj", "glb"}) {
    SCOPED_TRACE(format);
    const nlohmann::json& f = seen[format];
    ASSERT_FALSE(f.contains("error")) << f.dump();
    EXPECT_EQ(f["faces"].get<int64_t>(), mesh["triangles"].get<int64_t>());
    ASSERT_EQ(f["base_color_images"].size(), 1u) << f.dump();
    EXPECT_EQ(f["base_color_images"][0]["size"][0], mesh["texture"]["width"]);
    EXPECT_EQ(f["base_color_images"][0]["size"][1], mesh["texture"]["height"]);
    for (int a = 0; a < 2; ++a) {
      EXPECT_GE(f["uv_min"][a].get<double>(), 0.0);
      EXPECT_LE(f["uv_max"][a].get<double>(), 1.0);
    }
  }
}

}  // namespace
}  // namespace perf
