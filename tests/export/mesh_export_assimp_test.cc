// The mesh files against an independent reader: Assimp's command-line tool (Debian
// assimp-utils) must import each of PLY, OBJ and GLB with the mesh's vertex and face counts and
// find its vertex colours. Skips with a message when `assimp` is not installed.
#include <gtest/gtest.h>

#include <regex>
#include <sstream>
#include <string>

#include "common/atomic_file.h"
#include "export/mesh_export.h"
#include "export/mesh_texture.h"
#include "tests/export/synthetic_volume.h"
#include "tests/test_util.h"

namespace perf::exporter {
namespace {

// The integer after `label` in `text` (e.g. "Vertices:           8250"), or -1.
long long Count(const std::string& text, const std::string& label) {
  std::smatch m;
  if (!std::regex_search(text, m, std::regex(label + R"(\s*(\d+))"))) return -1;
  return std::stoll(m[1]);
}

TEST(MeshAssimpTest, AssimpImportsEveryFormatWithItsCountsAndColours) {
  if (perf::test::RunCommand("command -v assimp").exit_code != 0) {
    GTEST_SKIP() << "assimp not found (Debian package assimp-utils); skipping the independent check";
  }
  recon::Checkpoint c = test::EmptyCheckpoint(48);
  test::Paint(&c, test::SmoothSphere(test::LocalToWorld(c, {0.1, -0.2, 0.05}), 0.8, 0.03), {0.8f, 0.4f, 0.2f});
  const Mesh mesh = ExtractMesh(c, {});
  ASSERT_FALSE(mesh.triangles.empty());
  perf::test::TempDir dir;
  WritePly(dir / "sphere.ply", mesh);
  WriteObj(dir / "sphere.obj", mesh);
  WriteGlb(dir / "sphere.glb", mesh);
  for (const char* name : {"sphere.ply", "sphere.obj", "sphere.glb"}) {
    SCOPED_TRACE(name);
    const std::string file = (dir / name).string();
    // `info` validates the scene and joins identical vertices (the OBJ importer splits them per
    // face corner); it must find exactly our mesh.
    const perf::test::CommandResult info = perf::test::RunCommand("assimp info '" + file + "'");
    ASSERT_EQ(info.exit_code, 0) << info.output;
    EXPECT_EQ(Count(info.output, "Meshes:"), 1) << info.output;
    EXPECT_EQ(Count(info.output, "Vertices:"), static_cast<long long>(mesh.positions.size())) << info.output;
    EXPECT_EQ(Count(info.output, "Faces:"), static_cast<long long>(mesh.triangles.size())) << info.output;
    EXPECT_NE(info.output.find("Primitive Types:    triangles"), std::string::npos) << info.output;
    // The XML dump lists a colour per vertex.
    const std::string xml = (dir / (std::string(name) + ".xml")).string();
    const perf::test::CommandResult dump = perf::test::RunCommand("assimp dump '" + file + "' '" + xml + "' -x");
    ASSERT_EQ(dump.exit_code, 0) << dump.output;
    const std::string text = ReadFileToString(xml);
    const long long positions = Count(text, "<Positions num=\"");
    EXPECT_GE(positions, static_cast<long long>(mesh.positions.size()));
    EXPECT_EQ(Count(text, "<Colors num=\""), positions) << "no vertex colours read";
  }
}

// The textured OBJ (+ MTL + PNG) and GLB as assimp reads them: our triangles, one material with
// the texture (the PNG beside the OBJ, the one embedded in the GLB), and a texture coordinate in
// [0, 1] at every corner.
TEST(MeshAssimpTest, AssimpImportsTheTexturedObjAndGlbWithTheirTextureAndUvs) {
  if (perf::test::RunCommand("command -v assimp").exit_code != 0) {
    GTEST_SKIP() << "assimp not found (Debian package assimp-utils); skipping the independent check";
  }
  recon::Checkpoint c = test::EmptyCheckpoint(32);
  test::Paint(&c, test::SmoothSphere(test::LocalToWorld(c, {0.1, -0.2, 0.05}), 0.8, 0.03), {0.8f, 0.4f, 0.2f});
  const TexturedMesh t = BakeTexture(ExtractMesh(c, {}), ColourSampler(c));
  ASSERT_FALSE(t.mesh.triangles.empty());
  perf::test::TempDir dir;
  WriteStreamAtomically(dir / "mesh.obj", [&](std::ostream& s) { WriteTexturedObj(s, t, "mesh.mtl"); });
  WriteStreamAtomically(dir / "mesh.mtl", [&](std::ostream& s) { WriteMtl(s, "mesh.png"); });
  const std::string png = TexturePng(t);
  WriteFileAtomically(dir / "mesh.png", png);
  WriteStreamAtomically(dir / "mesh.glb", [&](std::ostream& s) { WriteGlb(s, t.mesh, t.uvs, png); });
  for (const char* name : {"mesh.obj", "mesh.glb"}) {
    SCOPED_TRACE(name);
    const std::string file = (dir / name).string();
    const perf::test::CommandResult info = perf::test::RunCommand("assimp info '" + file + "'");
    ASSERT_EQ(info.exit_code, 0) << info.output;
    EXPECT_EQ(Count(info.output, "Faces:"), static_cast<long long>(t.mesh.triangles.size())) << info.output;
    EXPECT_EQ(Count(info.output, "Materials:"), 1) << info.output;
    const bool glb = std::string(name) == "mesh.glb";
    if (glb) {
      EXPECT_EQ(Count(info.output, "Textures \\(embed.\\):"), 1) << info.output;
    }
    const std::string xml = (dir / (std::string(name) + ".xml")).string();
    ASSERT_EQ(perf::test::RunCommand("assimp dump '" + file + "' '" + xml + "' -x").exit_code, 0);
    const std::string text = ReadFileToString(xml);
    if (!glb) {
      EXPECT_NE(text.find("mesh.png"), std::string::npos) << "the material names no texture";
    }
    const size_t at = text.find("<TextureCoords");
    ASSERT_NE(at, std::string::npos) << "no texture coordinates read";
    // The coordinates: pairs "u v" (num_components="2") up to the closing tag, each in [0, 1].
    const size_t begin = text.find('>', at) + 1, end = text.find("</TextureCoords>", begin);
    EXPECT_NE(text.substr(at, begin - at).find("num_components=\"2\""), std::string::npos);
    std::istringstream values(text.substr(begin, end - begin));
    int64_t count = 0, outside = 0;
    for (double u, v; values >> u >> v; ++count) outside += u < 0 || u > 1 || v < 0 || v > 1;
    EXPECT_EQ(count, 3 * static_cast<int64_t>(t.mesh.triangles.size()));
    EXPECT_EQ(outside, 0);
  }
}

}  // namespace
}  // namespace perf::exporter
