// Mesh export: the iso-surface of synthetic spheres in a rotated, off-centre, anisotropic box
// against the true sphere (closed, outward, area and volume), vertex colours, component
// filtering, closing at the box wall, and the three writers read back byte by byte.
#include "export/mesh_export.h"
#include "export/mesh_simplify.h"
#include "export/mesh_texture.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <set>
#include <sstream>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "export/vdb_export.h"
#include "tests/export/synthetic_volume.h"
#include "tests/test_util.h"

namespace perf::exporter {
namespace {

namespace fs = std::filesystem;
using test::Vec3;

constexpr int kN = 64;
constexpr double kRadius = 0.8;
constexpr std::array<float, 3> kSrgb = {0.8f, 0.4f, 0.2f};
const Vec3 kSphereLocal = {0.1, -0.2, 0.05};

// Every undirected edge is used by exactly two triangles, once in each direction (closed and
// consistently oriented).
void ExpectClosedAndConsistent(const Mesh& mesh) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& t : mesh.triangles) {
    for (int e = 0; e < 3; ++e) ++directed[{t[e], t[(e + 1) % 3]}];
  }
  int64_t bad = 0;
  for (const auto& [edge, count] : directed) {
    const auto reverse = directed.find({edge.second, edge.first});
    if (count != 1 || reverse == directed.end() || reverse->second != 1) ++bad;
  }
  EXPECT_EQ(bad, 0) << "of " << directed.size() << " directed edges";
}

Vec3 ToLocal(const recon::Checkpoint& c, const std::array<float, 3>& p) { return test::WorldToLocal(c, {p[0], p[1], p[2]}); }

class MeshExportTest : public ::testing::Test {
 protected:
  static recon::Checkpoint SmoothSphere() {
    recon::Checkpoint c = test::EmptyCheckpoint(kN);
    test::FillColours(&c, {0.1f, 0.9f, 0.5f});
    test::Paint(&c, test::SmoothSphere(test::LocalToWorld(c, kSphereLocal), kRadius, 0.03), kSrgb);
    return c;
  }
  perf::test::TempDir dir_;
};

TEST_F(MeshExportTest, SphereIsClosedOutwardWithTheTrueAreaAndVolume) {
  const recon::Checkpoint c = SmoothSphere();
  const Mesh mesh = ExtractMesh(c, {});
  ASSERT_GT(mesh.triangles.size(), 1000u);
  EXPECT_EQ(mesh.components_found, 1);
  EXPECT_EQ(mesh.components_kept, 1);
  ExpectClosedAndConsistent(mesh);
  const double area = MeshArea(mesh), volume = MeshVolume(mesh);
  const double true_area = 4 * std::numbers::pi * kRadius * kRadius;
  const double true_volume = 4.0 / 3 * std::numbers::pi * kRadius * kRadius * kRadius;
  std::printf("sphere n=%d: %zu vertices, %zu triangles, area %.5f (true %.5f), volume %.5f (true %.5f)\n", kN,
              mesh.positions.size(), mesh.triangles.size(), area, true_area, volume, true_volume);
  EXPECT_NEAR(area / true_area, 1, 0.05);
  EXPECT_NEAR(volume / true_volume, 1, 0.05);  // positive: counter-clockwise seen from outside
  // Every vertex lies on the sphere, within a cell.
  const Vec3 centre = test::LocalToWorld(c, kSphereLocal);
  double worst = 0;
  for (const auto& p : mesh.positions) {
    worst = std::max(worst, std::abs(test::Distance({p[0], p[1], p[2]}, centre) - kRadius));
  }
  EXPECT_LT(worst, 0.5 * 2.0 / kN);
  // Each triangle's normal points away from the centre.
  int64_t inward = 0;
  for (const auto& t : mesh.triangles) {
    Vec3 a, b, m;
    for (int k = 0; k < 3; ++k) {
      a[k] = mesh.positions[t[1]][k] - mesh.positions[t[0]][k];
      b[k] = mesh.positions[t[2]][k] - mesh.positions[t[0]][k];
      m[k] = (mesh.positions[t[0]][k] + mesh.positions[t[1]][k] + mesh.positions[t[2]][k]) / 3 - centre[k];
    }
    const Vec3 nrm = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    if (nrm[0] * m[0] + nrm[1] * m[1] + nrm[2] * m[2] <= 0) ++inward;
  }
  EXPECT_EQ(inward, 0);
  // The colour given, at every vertex.
  ASSERT_EQ(mesh.colours.size(), mesh.positions.size());
  for (const auto& rgb : mesh.colours) {
    for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(rgb[ch], kSrgb[ch], 1e-6);
  }
}

// --mesh-triangles: the sphere simplified to a tenth stays closed, outward and the same sphere,
// with every kept vertex's colour; within the budget nothing changes.
TEST_F(MeshExportTest, SimplifiedSphereStaysClosedAndTheSameShape) {
  Mesh mesh = ExtractMesh(SmoothSphere(), MeshOptions{});
  const Mesh full = mesh;
  const int64_t target = static_cast<int64_t>(full.triangles.size()) / 10;
  const SimplifyResult r = SimplifyMesh(&mesh, target);
  EXPECT_EQ(r.triangles_before, static_cast<int64_t>(full.triangles.size()));
  EXPECT_LE(r.triangles_after, target);
  EXPECT_GT(r.triangles_after, target / 2);
  EXPECT_EQ(r.triangles_after, static_cast<int64_t>(mesh.triangles.size()));
  ExpectClosedAndConsistent(mesh);
  ASSERT_EQ(mesh.colours.size(), mesh.positions.size());
  EXPECT_NEAR(MeshVolume(mesh), MeshVolume(full), 0.03 * MeshVolume(full));
  EXPECT_GT(MeshVolume(mesh), 0) << "outward";
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    const auto at = std::find(full.positions.begin(), full.positions.end(), mesh.positions[v]);
    ASSERT_NE(at, full.positions.end()) << "a vertex moved";
    EXPECT_EQ(mesh.colours[v], full.colours[static_cast<size_t>(at - full.positions.begin())]);
  }
  Mesh same = full;
  EXPECT_EQ(SimplifyMesh(&same, 0).triangles_after, r.triangles_before);
  EXPECT_EQ(SimplifyMesh(&same, r.triangles_before).triangles_after, r.triangles_before);
  EXPECT_EQ(same.positions, full.positions);
}

// The baked texture: every texel takes the colour grid's colour at its point on the surface (the
// sphere's, not the different colour of the empty cells around it), each triangle has a cell of
// its own, and the OBJ points at it through its material.
TEST_F(MeshExportTest, BakedTextureHoldsTheSurfaceColourInACellPerTriangle) {
  // A hard sphere: its cells alone have its colour; the empty cells around it another.
  recon::Checkpoint c = test::EmptyCheckpoint(kN);
  test::FillColours(&c, {0.1f, 0.9f, 0.5f});
  test::Paint(&c, test::HardSphere(test::LocalToWorld(c, kSphereLocal), kRadius), kSrgb);
  const Mesh mesh = ExtractMesh(c, MeshOptions{});
  const TexturedMesh t = BakeTexture(mesh, ColourSampler(c));
  const size_t n = mesh.triangles.size();
  ASSERT_EQ(t.uvs.size(), 3 * n);
  ASSERT_EQ(t.rgb.size(), static_cast<size_t>(3 * t.width * t.height));
  EXPECT_GE(t.cell, 4);
  EXPECT_LE(std::max(t.width, t.height), 2048);
  std::set<std::pair<int, int>> cells;
  for (size_t k = 0; k < n; ++k) {
    float lo[2] = {1, 1}, hi[2] = {0, 0};
    for (int corner = 0; corner < 3; ++corner) {
      for (int a = 0; a < 2; ++a) {
        const float v = t.uvs[3 * k + corner][a];
        ASSERT_TRUE(v >= 0 && v <= 1) << v;
        lo[a] = std::min(lo[a], v), hi[a] = std::max(hi[a], v);
      }
    }
    const int cx = static_cast<int>(lo[0] * t.width) / t.cell, cy = static_cast<int>(lo[1] * t.height) / t.cell;
    EXPECT_EQ(static_cast<int>(hi[0] * t.width - 1e-3) / t.cell, cx) << "a triangle leaves its cell";
    EXPECT_EQ(static_cast<int>(hi[1] * t.height - 1e-3) / t.cell, cy);
    EXPECT_TRUE(cells.insert({cx, cy}).second) << "two triangles share a cell";
  }
  int64_t off = 0;
  for (size_t k = 0; k < n; ++k) {  // every texel of every triangle's cell
    const int x0 = static_cast<int>(k % (t.width / t.cell)) * t.cell, y0 = static_cast<int>(k / (t.width / t.cell)) * t.cell;
    for (int j = 0; j < t.cell; ++j) {
      for (int i = 0; i < t.cell; ++i) {
        const uint8_t* p = &t.rgb[3 * ((y0 + j) * static_cast<size_t>(t.width) + x0 + i)];
        for (int ch = 0; ch < 3; ++ch) off += std::abs(p[ch] - std::lround(255 * kSrgb[ch])) > 6;
      }
    }
  }
  EXPECT_EQ(off, 0) << "texels away from the sphere's colour";
  EXPECT_EQ(TexturePng(t).substr(1, 3), "PNG");
  std::ostringstream obj, mtl;
  WriteTexturedObj(obj, t, "mesh.mtl");
  WriteMtl(mtl, "mesh.png");
  const std::string text = obj.str();
  EXPECT_NE(text.find("mtllib mesh.mtl\nusemtl "), std::string::npos);
  size_t vt = 0, faces = 0;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    vt += line.rfind("vt ", 0) == 0;
    faces += line.rfind("f ", 0) == 0 && line.find('/') != std::string::npos;
  }
  EXPECT_EQ(vt, 3 * n);
  EXPECT_EQ(faces, n);
  EXPECT_NE(mtl.str().find("map_Kd mesh.png"), std::string::npos);
  EXPECT_TRUE(BakeTexture(Mesh{}, ColourSampler(c)).rgb.empty());
  // Simplified, a large triangle of the stair-stepped surface crosses empty cells: those texels
  // take the triangle's vertex colours, not the empty cells' colour.
  Mesh small = mesh;
  SimplifyMesh(&small, 500);
  const TexturedMesh s = BakeTexture(small, ColourSampler(c));
  int64_t far = 0;
  const size_t used_rows = (small.triangles.size() + s.width / s.cell - 1) / (s.width / s.cell);
  for (size_t i = 0; i < 3 * s.width * used_rows * s.cell; ++i) {
    const size_t cell = (i / 3 % s.width) / s.cell + (i / 3 / s.width) / s.cell * (s.width / s.cell);
    if (cell < small.triangles.size()) far += std::abs(s.rgb[i] - std::lround(255 * kSrgb[i % 3])) > 6;
  }
  EXPECT_EQ(far, 0);
}

TEST_F(MeshExportTest, MirroringBoxRotationKeepsTheSurfaceOutward) {
  recon::Checkpoint c = test::EmptyCheckpoint(32);
  for (int r = 0; r < 3; ++r) c.placement.box_rotation[3 * r + 1] *= -1;  // box y axis reversed
  test::Paint(&c, test::SmoothSphere(test::LocalToWorld(c, kSphereLocal), kRadius, 0.05), kSrgb);
  const Mesh mesh = ExtractMesh(c, {});
  ExpectClosedAndConsistent(mesh);
  EXPECT_NEAR(MeshVolume(mesh) / (4.0 / 3 * std::numbers::pi * std::pow(kRadius, 3)), 1, 0.05);
}

TEST_F(MeshExportTest, HigherIsoLevelGivesASmallerSurface) {
  const recon::Checkpoint c = SmoothSphere();
  MeshOptions options;
  options.iso_opacity = 0.9;
  const double volume = MeshVolume(ExtractMesh(c, options));
  // Opacity 0.9 at d = R - w ln 9 (the logistic profile).
  const double r = kRadius - 0.03 * std::log(9.0);
  EXPECT_NEAR(volume / (4.0 / 3 * std::numbers::pi * r * r * r), 1, 0.05);
}

TEST_F(MeshExportTest, VertexColoursComeFromTheOpaqueCellsOnly) {
  // A hard sphere in cells of another colour (empty space keeps whatever the solver left): the
  // surface lies half-way between opaque and empty cells, and takes the opaque cells' colour.
  recon::Checkpoint c = test::EmptyCheckpoint(32);
  test::FillColours(&c, {0.0f, 1.0f, 1.0f});
  test::Paint(&c, test::HardSphere(test::LocalToWorld(c, kSphereLocal), kRadius), kSrgb);
  const Mesh mesh = ExtractMesh(c, {});
  ASSERT_FALSE(mesh.triangles.empty());
  ExpectClosedAndConsistent(mesh);
  for (const auto& rgb : mesh.colours) {
    for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(rgb[ch], kSrgb[ch], 1e-6);
  }
}

TEST_F(MeshExportTest, ColourVariesLikeTheGrid) {
  // Red grows linearly along the box's x axis: trilinear sampling gives it back at the vertices
  // (up to the opacity weighting, within a cell's worth of the gradient).
  recon::Checkpoint c = SmoothSphere();
  for (int k = 0; k < kN; ++k) {
    for (int j = 0; j < kN; ++j) {
      for (int i = 0; i < kN; ++i) c.params[recon::GridParam(recon::GridCell(kN, i, j, k), 0)] = (i + 0.5f) / kN;
    }
  }
  const Mesh mesh = ExtractMesh(c, {});
  ASSERT_FALSE(mesh.positions.empty());
  double worst = 0;
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    const double expected = (ToLocal(c, mesh.positions[v])[0] + 1.0) / 2.0;  // box x in [-1, 1]
    worst = std::max(worst, std::abs(mesh.colours[v][0] - expected));
    ASSERT_NEAR(mesh.colours[v][1], kSrgb[1], 1e-6);
  }
  EXPECT_LT(worst, 1.0 / kN);
}

TEST_F(MeshExportTest, SmallFarComponentIsDroppedByDefault) {
  recon::Checkpoint c = SmoothSphere();
  test::Paint(&c, test::SmoothSphere(test::LocalToWorld(c, {0.0, 1.2, 0.0}), 0.12, 0.03), {0.f, 0.f, 1.f});
  const Mesh filtered = ExtractMesh(c, {});
  EXPECT_EQ(filtered.components_found, 2);
  EXPECT_EQ(filtered.components_kept, 1);
  ExpectClosedAndConsistent(filtered);
  for (const auto& p : filtered.positions) ASSERT_LT(ToLocal(c, p)[1], 0.7);

  MeshOptions all;
  all.min_component_fraction = 0;
  const Mesh everything = ExtractMesh(c, all);
  EXPECT_EQ(everything.components_found, 2);
  EXPECT_EQ(everything.components_kept, 2);
  EXPECT_GT(everything.triangles.size(), filtered.triangles.size());
  ExpectClosedAndConsistent(everything);
  const double blob = 4.0 / 3 * std::numbers::pi * 0.12 * 0.12 * 0.12;
  // 3 to 4 cells across: the mesher's inward bias on a convex surface is ~0.1 cell, 4 % of R.
  EXPECT_NEAR(MeshVolume(everything) - MeshVolume(filtered), blob, 0.2 * blob);
  // Only the largest: the same as the default here.
  MeshOptions largest;
  largest.min_component_fraction = 1;
  EXPECT_EQ(ExtractMesh(c, largest).triangles.size(), filtered.triangles.size());
}

TEST_F(MeshExportTest, ObjectCutByTheBoxWallIsClosedAtTheWall) {
  // A box full of opaque cells: the surface is the box itself, closed by caps at the walls.
  recon::Checkpoint c = test::EmptyCheckpoint(kN);
  test::Paint(&c, [](const Vec3&) { return 1.0; }, kSrgb);
  const Mesh mesh = ExtractMesh(c, {});
  ExpectClosedAndConsistent(mesh);
  const double* s = c.placement.box_size;
  const double true_volume = s[0] * s[1] * s[2];
  const double true_area = 2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]);
  // The faces lie on the walls; the dual mesher bevels the box's edges over about a cell (a
  // surface of 2 cells across an edge becomes one of ~1.6): -1.3 % area at this size, 5 % at n 16.
  EXPECT_NEAR(MeshVolume(mesh) / true_volume, 1, 0.01);
  EXPECT_NEAR(MeshArea(mesh) / true_area, 1, 0.025);
  for (const auto& p : mesh.positions) {
    const Vec3 local = ToLocal(c, p);
    for (int a = 0; a < 3; ++a) ASSERT_LE(std::abs(local[a]), s[a] / 2 + 1e-5) << a;
  }

  // A sphere that pokes out of the box: capped where the wall cuts it.
  recon::Checkpoint cut = test::EmptyCheckpoint(kN);
  test::Paint(&cut, test::SmoothSphere(test::LocalToWorld(cut, {0.7, 0.0, 0.0}), kRadius, 0.03), kSrgb);
  const Mesh capped = ExtractMesh(cut, {});
  ExpectClosedAndConsistent(capped);
  // Spherical cap beyond x = 1 (h = 0.5) removed: V = pi h^2 (3 R - h) / 3.
  const double h = 0.7 + kRadius - 1.0;
  const double expected = 4.0 / 3 * std::numbers::pi * std::pow(kRadius, 3) - std::numbers::pi * h * h * (3 * kRadius - h) / 3;
  EXPECT_NEAR(MeshVolume(capped) / expected, 1, 0.05);

  // The same with adaptive meshing: fewer, larger triangles, still closed. (Adaptivity is
  // strong on a smooth field: 0.01 already keeps ~1/4 of the triangles; 0.25 keeps ~1/13 and
  // loses 5 % of the volume to chords.)
  MeshOptions adaptive;
  adaptive.adaptivity = 0.01;
  const Mesh coarse = ExtractMesh(cut, adaptive);
  ExpectClosedAndConsistent(coarse);
  EXPECT_LT(coarse.triangles.size(), capped.triangles.size() / 2);
  EXPECT_NEAR(MeshVolume(coarse) / expected, 1, 0.05);
}

TEST_F(MeshExportTest, NothingAboveTheIsoLevelIsAnEmptyMesh) {
  recon::Checkpoint c = test::EmptyCheckpoint(8);
  Mesh mesh = ExtractMesh(c, {});
  EXPECT_TRUE(mesh.positions.empty());
  EXPECT_TRUE(mesh.triangles.empty());
  test::Paint(&c, [](const Vec3&) { return 0.3; }, kSrgb);
  mesh = ExtractMesh(c, {});
  EXPECT_TRUE(mesh.triangles.empty());
  EXPECT_EQ(mesh.components_found, 0);
  // The writers still write valid (empty) files.
  WritePly(dir_ / "empty.ply", mesh);
  WriteObj(dir_ / "empty.obj", mesh);
  WriteGlb(dir_ / "empty.glb", mesh);
  const std::string glb = ReadFileToString(dir_ / "empty.glb");
  ASSERT_GE(glb.size(), 20u);
  uint32_t json_length;
  std::memcpy(&json_length, glb.data() + 12, 4);
  const nlohmann::json doc = nlohmann::json::parse(glb.substr(20, json_length));
  EXPECT_FALSE(doc.contains("buffers"));
  EXPECT_EQ(doc["nodes"].size(), 1u);
}

// ---- Writers, on the smooth sphere ----

class MeshWriterTest : public MeshExportTest {
 protected:
  void SetUp() override { mesh_ = ExtractMesh(SmoothSphere(), {}); }
  Mesh mesh_;
};

template <class T>
T Get(const std::string& s, size_t offset) {
  T v;
  std::memcpy(&v, s.data() + offset, sizeof(T));
  return v;
}

TEST_F(MeshWriterTest, PlyHeaderCountsAndBinaryBody) {
  const fs::path path = dir_ / "sphere.ply";
  WritePly(path, mesh_);
  const std::string bytes = ReadFileToString(path);
  const size_t end = bytes.find("end_header\n");
  ASSERT_NE(end, std::string::npos);
  std::istringstream header(bytes.substr(0, end));
  std::string line;
  std::vector<std::string> lines;
  while (std::getline(header, line)) lines.push_back(line);
  ASSERT_GE(lines.size(), 3u);
  EXPECT_EQ(lines[0], "ply");
  EXPECT_EQ(lines[1], "format binary_little_endian 1.0");
  const std::vector<std::string> expected_properties = {
      "element vertex " + std::to_string(mesh_.positions.size()), "property float x", "property float y",
      "property float z", "property uchar red", "property uchar green", "property uchar blue",
      "element face " + std::to_string(mesh_.triangles.size()), "property list uchar int vertex_indices"};
  std::vector<std::string> properties;
  for (const std::string& l : lines) {
    if (l.rfind("element", 0) == 0 || l.rfind("property", 0) == 0) properties.push_back(l);
  }
  EXPECT_EQ(properties, expected_properties);
  const size_t body = end + std::strlen("end_header\n");
  const size_t nv = mesh_.positions.size(), nt = mesh_.triangles.size();
  ASSERT_EQ(bytes.size() - body, nv * 15 + nt * 13);
  for (size_t v : {size_t{0}, nv / 2, nv - 1}) {
    const size_t o = body + 15 * v;
    for (int a = 0; a < 3; ++a) EXPECT_EQ(Get<float>(bytes, o + 4 * a), mesh_.positions[v][a]);
    for (int ch = 0; ch < 3; ++ch) {
      EXPECT_EQ(static_cast<uint8_t>(bytes[o + 12 + ch]), std::lround(mesh_.colours[v][ch] * 255));
    }
  }
  for (size_t t : {size_t{0}, nt - 1}) {
    const size_t o = body + 15 * nv + 13 * t;
    EXPECT_EQ(static_cast<uint8_t>(bytes[o]), 3);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(Get<int32_t>(bytes, o + 1 + 4 * k), static_cast<int32_t>(mesh_.triangles[t][k]));
  }
}

TEST_F(MeshWriterTest, ObjLinesAndVertexColours) {
  const fs::path path = dir_ / "sphere.obj";
  WriteObj(path, mesh_);
  std::ifstream in(path);
  std::string line;
  size_t v = 0, f = 0, comments = 0;
  bool says_colours = false;
  while (std::getline(in, line)) {
    if (line.rfind("v ", 0) == 0) {
      std::istringstream ss(line.substr(2));
      std::vector<double> x;
      double d;
      while (ss >> d) x.push_back(d);
      ASSERT_EQ(x.size(), 6u) << line;
      for (int a = 0; a < 3; ++a) ASSERT_EQ(static_cast<float>(x[a]), mesh_.positions[v][a]) << line;
      for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(x[3 + ch], mesh_.colours[v][ch], 1e-6) << line;
      ++v;
    } else if (line.rfind("f ", 0) == 0) {
      std::istringstream ss(line.substr(2));
      uint32_t a, b, c;
      ASSERT_TRUE(ss >> a >> b >> c) << line;
      ASSERT_EQ((std::array<uint32_t, 3>{a - 1, b - 1, c - 1}), mesh_.triangles[f]);
      ++f;
    } else if (line.rfind("#", 0) == 0) {
      ++comments;
      says_colours = says_colours || line.find("v x y z r g b") != std::string::npos;
    } else {
      ADD_FAILURE() << "unexpected line: " << line;
    }
  }
  EXPECT_EQ(v, mesh_.positions.size());
  EXPECT_EQ(f, mesh_.triangles.size());
  EXPECT_TRUE(says_colours);
  EXPECT_GE(comments, 1u);
}

TEST_F(MeshWriterTest, GlbContainerJsonAndBuffers) {
  const fs::path path = dir_ / "sphere.glb";
  WriteGlb(path, mesh_);
  const std::string bytes = ReadFileToString(path);
  ASSERT_GE(bytes.size(), 28u);
  EXPECT_EQ(bytes.substr(0, 4), "glTF");
  EXPECT_EQ(Get<uint32_t>(bytes, 4), 2u);
  EXPECT_EQ(Get<uint32_t>(bytes, 8), bytes.size());
  const uint32_t json_length = Get<uint32_t>(bytes, 12);
  EXPECT_EQ(bytes.substr(16, 4), "JSON");
  EXPECT_EQ(json_length % 4, 0u);
  const size_t bin_at = 20 + json_length;
  ASSERT_LE(bin_at + 8, bytes.size());
  EXPECT_EQ(bin_at % 4, 0u);
  const uint32_t bin_length = Get<uint32_t>(bytes, bin_at);
  EXPECT_EQ(bytes.substr(bin_at + 4, 4), std::string("BIN\0", 4));
  EXPECT_EQ(bin_length % 4, 0u);
  EXPECT_EQ(bin_at + 8 + bin_length, bytes.size());

  const nlohmann::json doc = nlohmann::json::parse(bytes.substr(20, json_length));  // trailing spaces are JSON whitespace
  EXPECT_EQ(doc["asset"]["version"], "2.0");
  EXPECT_EQ(doc["asset"]["generator"], "PERF");
  EXPECT_EQ(doc["scene"], 0);
  EXPECT_EQ(doc["scenes"][0]["nodes"], nlohmann::json::array({0}));
  EXPECT_EQ(doc["nodes"][0]["mesh"], 0);
  ASSERT_EQ(doc["meshes"].size(), 1u);
  const nlohmann::json& prim = doc["meshes"][0]["primitives"][0];
  EXPECT_EQ(prim["mode"], 4);
  const nlohmann::json& accessors = doc["accessors"];
  const nlohmann::json& views = doc["bufferViews"];
  const size_t nv = mesh_.positions.size(), nt = mesh_.triangles.size();
  const nlohmann::json& pos = accessors[prim["attributes"]["POSITION"].get<int>()];
  const nlohmann::json& col = accessors[prim["attributes"]["COLOR_0"].get<int>()];
  const nlohmann::json& idx = accessors[prim["indices"].get<int>()];
  EXPECT_EQ(pos["count"], nv);
  EXPECT_EQ(pos["type"], "VEC3");
  EXPECT_EQ(pos["componentType"], 5126);
  EXPECT_EQ(col["count"], nv);
  EXPECT_EQ(col["type"], "VEC3");
  EXPECT_EQ(col["componentType"], 5126);
  EXPECT_EQ(idx["count"], 3 * nt);
  EXPECT_EQ(idx["type"], "SCALAR");
  EXPECT_EQ(idx["componentType"], 5125);
  // Views: consistent with the accessors, 4-byte aligned, inside the one buffer = BIN chunk.
  const uint64_t buffer_length = doc["buffers"][0]["byteLength"];
  EXPECT_FALSE(doc["buffers"][0].contains("uri"));
  EXPECT_LE(buffer_length, bin_length);
  EXPECT_GT(buffer_length + 4, bin_length);
  const size_t element_bytes[3] = {12, 12, 4};
  for (int a = 0; a < 3; ++a) {
    const nlohmann::json& acc = accessors[a];
    const nlohmann::json& view = views[acc["bufferView"].get<int>()];
    EXPECT_EQ(view["byteLength"].get<uint64_t>(), acc["count"].get<uint64_t>() * element_bytes[a]) << a;
    EXPECT_EQ(view["byteOffset"].get<uint64_t>() % 4, 0u);
    EXPECT_LE(view["byteOffset"].get<uint64_t>() + view["byteLength"].get<uint64_t>(), buffer_length);
  }
  // Values: positions and their bounds, linear colours, indices.
  const size_t data = bin_at + 8;
  const size_t pos_at = data + views[pos["bufferView"].get<int>()]["byteOffset"].get<size_t>();
  const size_t col_at = data + views[col["bufferView"].get<int>()]["byteOffset"].get<size_t>();
  const size_t idx_at = data + views[idx["bufferView"].get<int>()]["byteOffset"].get<size_t>();
  std::array<float, 3> lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  for (size_t v = 0; v < nv; ++v) {
    for (int a = 0; a < 3; ++a) {
      const float x = Get<float>(bytes, pos_at + 12 * v + 4 * a);
      ASSERT_EQ(x, mesh_.positions[v][a]);
      lo[a] = std::min(lo[a], x);
      hi[a] = std::max(hi[a], x);
    }
  }
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(pos["min"][a].get<float>(), lo[a]);
    EXPECT_EQ(pos["max"][a].get<float>(), hi[a]);
  }
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(Get<float>(bytes, col_at + 4 * ch), SrgbToLinear(kSrgb[ch]), 1e-6);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(Get<uint32_t>(bytes, idx_at + 4 * (3 * (nt - 1) + k)), mesh_.triangles[nt - 1][k]);
  // A non-metallic material (glTF's default is metallic).
  EXPECT_EQ(doc["materials"][prim["material"].get<int>()]["pbrMetallicRoughness"]["metallicFactor"], 0);
}

TEST_F(MeshWriterTest, UnwritablePathThrowsIoErrorAndLeavesNoFile) {
  const fs::path dir = dir_ / "missing";
  for (const char* name : {"m.ply", "m.obj", "m.glb"}) {
    const fs::path path = dir / name;
    try {
      const std::string ext = path.extension().string();
      if (ext == ".ply") WritePly(path, mesh_);
      if (ext == ".obj") WriteObj(path, mesh_);
      if (ext == ".glb") WriteGlb(path, mesh_);
      ADD_FAILURE() << "expected IoError for " << path;
    } catch (const IoError& e) {
      EXPECT_EQ(e.path(), path.string());
    }
  }
  EXPECT_FALSE(fs::exists(dir));
}

TEST_F(MeshWriterTest, StreamAndPathOverloadsWriteTheSameBytes) {
  std::ostringstream ply, obj, glb;
  WritePly(ply, mesh_);
  WriteObj(obj, mesh_);
  WriteGlb(glb, mesh_);
  WritePly(dir_ / "a.ply", mesh_);
  WriteObj(dir_ / "a.obj", mesh_);
  WriteGlb(dir_ / "a.glb", mesh_);
  EXPECT_EQ(ply.str(), ReadFileToString(dir_ / "a.ply"));
  EXPECT_EQ(obj.str(), ReadFileToString(dir_ / "a.obj"));
  EXPECT_EQ(glb.str(), ReadFileToString(dir_ / "a.glb"));
}

}  // namespace
}  // namespace perf::exporter
