#include "export/mesh_export.h"

#include <Eigen/Dense>
#include <openvdb/openvdb.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <numeric>
#include <nlohmann/json.hpp>
#include <string>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "export/vdb_export.h"

namespace perf::exporter {

namespace fs = std::filesystem;

static_assert(std::endian::native == std::endian::little, "PLY and GLB are written little-endian");

namespace {

using Vec3d = std::array<double, 3>;

Vec3d Sub(const Vec3d& a, const Vec3d& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3d Cross(const Vec3d& a, const Vec3d& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double Dot(const Vec3d& a, const Vec3d& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3d ToDouble(const std::array<float, 3>& p) { return {p[0], p[1], p[2]}; }

// Opacity of a cell across CellLength.
// cell: a stored cell, or -1 (an inactive brick's: empty).
double CellOpacity(const recon::Checkpoint& c, int64_t cell, double length) {
  if (cell < 0) return 0.0;
  const double sigma = c.params[recon::GridParam(cell, 3)];
  return sigma > 0 ? -std::expm1(-sigma * length) : 0.0;
}

// The colour at index-space point p (cell centres at integers): trilinear over the 8 nearest
// cell centres (clamped at the border, as the renderer's LinearCoord), each weight multiplied by
// the cell's opacity; plain trilinear where all 8 are empty.
// near_opaque: set to whether any of the 8 cells has opacity (else the colour is the plain one).
std::array<float, 3> SampleColour(const recon::Checkpoint& c, const openvdb::Vec3s& p, double length,
                                  bool* near_opaque = nullptr) {
  const int n = c.shape.n;
  int lo[3], hi[3];
  double f[3];
  for (int a = 0; a < 3; ++a) recon::LinearCoord<double>(static_cast<double>(p[a]) + 0.5, n, &lo[a], &hi[a], &f[a]);
  double weighted[3] = {0, 0, 0}, plain[3] = {0, 0, 0}, weight_sum = 0;
  for (int corner = 0; corner < 8; ++corner) {
    int idx[3];
    double w = 1;
    for (int a = 0; a < 3; ++a) {
      const bool up = (corner >> a) & 1;
      idx[a] = up ? hi[a] : lo[a];
      w *= up ? f[a] : 1 - f[a];
    }
    const int64_t cell = recon::StoredCell(c.shape, idx[0], idx[1], idx[2]);
    const double wa = w * CellOpacity(c, cell, length);
    for (int ch = 0; ch < 3; ++ch) {
      const double v = cell < 0 ? 0.0 : std::clamp(static_cast<double>(c.params[recon::GridParam(cell, ch)]), 0.0, 1.0);
      weighted[ch] += wa * v;
      plain[ch] += w * v;
    }
    weight_sum += wa;
  }
  std::array<float, 3> rgb;
  if (near_opaque != nullptr) *near_opaque = weight_sum > 1e-12;
  for (int ch = 0; ch < 3; ++ch) {
    rgb[ch] = static_cast<float>(weight_sum > 1e-12 ? weighted[ch] / weight_sum : plain[ch]);
  }
  return rgb;
}

class UnionFind {
 public:
  explicit UnionFind(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), uint32_t{0}); }
  uint32_t Find(uint32_t x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];  // path halving
    return x;
  }
  void Union(uint32_t a, uint32_t b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }

 private:
  std::vector<uint32_t> parent_;
};

}  // namespace

Mesh ExtractMesh(const recon::Checkpoint& c, const MeshOptions& options) {
  CheckExportable(c);
  openvdb::initialize();
  const double length = CellLength(c);

  // Opacity per cell in index space (identity transform; positions go to world below, in double).
  // Empty cells stay inactive; volumeToMesh reads them, and everything outside the box, as the
  // background 0, so the surface closes at the box wall (the tests check this, also adaptive).
  openvdb::FloatGrid::Ptr opacity = openvdb::FloatGrid::create(0.f);
  opacity->setGridClass(openvdb::GRID_FOG_VOLUME);  // inside = above the iso value
  bool reaches_iso = false;
  {
    openvdb::FloatGrid::Accessor acc = opacity->getAccessor();
    recon::ForEachStoredCell(c.shape, [&](int i, int j, int k, int64_t cell) {
      const double a = CellOpacity(c, cell, length);
      if (a <= 0) return;
      acc.setValue(openvdb::Coord(i, j, k), static_cast<float>(a));
      reaches_iso = reaches_iso || a >= options.iso_opacity;
    });
  }
  Mesh mesh;
  if (!reaches_iso) return mesh;

  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> vdb_triangles;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(*opacity, points, vdb_triangles, quads, options.iso_opacity,
                               std::clamp(options.adaptivity, 0.0, 1.0));
  opacity.reset();

  // Triangles. volumeToMesh orients a fog volume's polygons clockwise seen from outside (the
  // test's positive volume checks this); a mirroring box rotation flips them once more.
  const std::array<double, 12> a = WorldFromIndex(c);
  const double det = a[0] * (a[5] * a[10] - a[6] * a[9]) - a[1] * (a[4] * a[10] - a[6] * a[8]) +
                     a[2] * (a[4] * a[9] - a[5] * a[8]);
  const bool flip = !(det < 0);
  std::vector<std::array<uint32_t, 3>> triangles;
  triangles.reserve(vdb_triangles.size() + 2 * quads.size());
  auto add = [&](uint32_t p, uint32_t q, uint32_t r) {
    if (p == q || q == r || r == p) return;  // collapsed by adaptive meshing
    triangles.push_back(flip ? std::array<uint32_t, 3>{p, r, q} : std::array<uint32_t, 3>{p, q, r});
  };
  for (const openvdb::Vec3I& t : vdb_triangles) add(t[0], t[1], t[2]);
  for (const openvdb::Vec4I& q : quads) {
    // Split along the shorter diagonal (better-shaped triangles on curved parts).
    if ((points[q[0]] - points[q[2]]).lengthSqr() <= (points[q[1]] - points[q[3]]).lengthSqr()) {
      add(q[0], q[1], q[2]);
      add(q[0], q[2], q[3]);
    } else {
      add(q[0], q[1], q[3]);
      add(q[1], q[2], q[3]);
    }
  }

  // Connected components over shared vertices; keep those with enough triangles.
  UnionFind uf(points.size());
  for (const auto& t : triangles) {
    uf.Union(t[0], t[1]);
    uf.Union(t[0], t[2]);
  }
  std::vector<int64_t> tri_count(points.size(), 0);
  for (const auto& t : triangles) ++tri_count[uf.Find(t[0])];
  const int64_t largest = triangles.empty() ? 0 : *std::max_element(tri_count.begin(), tri_count.end());
  const double min_triangles = std::clamp(options.min_component_fraction, 0.0, 1.0) * static_cast<double>(largest);
  for (int64_t count : tri_count) {
    if (count == 0) continue;
    ++mesh.components_found;
    if (static_cast<double>(count) >= min_triangles) ++mesh.components_kept;
  }

  // Compact the kept vertices, to world, with colours.
  constexpr uint32_t kUnused = 0xffffffffu;
  std::vector<uint32_t> remap(points.size(), kUnused);
  mesh.triangles.reserve(triangles.size());
  for (const auto& t : triangles) {
    if (static_cast<double>(tri_count[uf.Find(t[0])]) < min_triangles) continue;
    std::array<uint32_t, 3> out;
    for (int v = 0; v < 3; ++v) {
      uint32_t& m = remap[t[v]];
      if (m == kUnused) {
        m = static_cast<uint32_t>(mesh.positions.size());
        const openvdb::Vec3s& p = points[t[v]];
        std::array<float, 3> w;
        for (int r = 0; r < 3; ++r) {
          w[r] = static_cast<float>(a[4 * r] * p[0] + a[4 * r + 1] * p[1] + a[4 * r + 2] * p[2] + a[4 * r + 3]);
        }
        mesh.positions.push_back(w);
        mesh.colours.push_back(SampleColour(c, p, length));
      }
      out[v] = m;
    }
    mesh.triangles.push_back(out);
  }
  return mesh;
}

ColourSampler::ColourSampler(const recon::Checkpoint& checkpoint)
    : checkpoint_(checkpoint), length_(CellLength(checkpoint)) {
  const std::array<double, 12> a = WorldFromIndex(checkpoint);
  Eigen::Matrix3d m;
  Eigen::Vector3d t;
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) m(r, k) = a[4 * r + k];
    t[r] = a[4 * r + 3];
  }
  const Eigen::Matrix3d inv = m.inverse();
  const Eigen::Vector3d shift = -inv * t;
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) index_from_world_[4 * r + k] = inv(r, k);
    index_from_world_[4 * r + 3] = shift[r];
  }
}

std::array<float, 3> ColourSampler::At(const std::array<double, 3>& w, bool* near_opaque) const {
  const std::array<double, 12>& a = index_from_world_;
  openvdb::Vec3s p;
  for (int r = 0; r < 3; ++r) p[r] = static_cast<float>(a[4 * r] * w[0] + a[4 * r + 1] * w[1] + a[4 * r + 2] * w[2] + a[4 * r + 3]);
  return SampleColour(checkpoint_, p, length_, near_opaque);
}

double MeshArea(const Mesh& mesh) {
  double area = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3d p = ToDouble(mesh.positions[t[0]]);
    const Vec3d c = Cross(Sub(ToDouble(mesh.positions[t[1]]), p), Sub(ToDouble(mesh.positions[t[2]]), p));
    area += 0.5 * std::sqrt(Dot(c, c));
  }
  return area;
}

double MeshVolume(const Mesh& mesh) {
  // Sum of signed tetrahedra (origin, a, b, c); relative to the first vertex to limit
  // cancellation far from the origin.
  if (mesh.positions.empty()) return 0;
  const Vec3d o = ToDouble(mesh.positions[0]);
  double volume = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3d p = Sub(ToDouble(mesh.positions[t[0]]), o), q = Sub(ToDouble(mesh.positions[t[1]]), o),
                r = Sub(ToDouble(mesh.positions[t[2]]), o);
    volume += Dot(p, Cross(q, r));
  }
  return volume / 6;
}

// ---- Writers ----

namespace {

template <class T>
void Put(std::string* buf, const T& v) {
  buf->append(reinterpret_cast<const char*>(&v), sizeof(T));
}

uint8_t ToByte(float v) { return static_cast<uint8_t>(std::lround(std::clamp(v, 0.f, 1.f) * 255.f)); }

void CheckMesh(const Mesh& mesh) {
  PERF_CHECK(mesh.colours.size() == mesh.positions.size());
  for (const auto& t : mesh.triangles) {
    PERF_CHECK(t[0] < mesh.positions.size() && t[1] < mesh.positions.size() && t[2] < mesh.positions.size());
  }
}

}  // namespace

void WritePly(std::ostream& out, const Mesh& mesh) {
  CheckMesh(mesh);
  out << "ply\nformat binary_little_endian 1.0\n"
      << "comment PERF mesh: positions in world units of the source frame, vertex colours sRGB\n"
      << "element vertex " << mesh.positions.size() << "\n"
      << "property float x\nproperty float y\nproperty float z\n"
      << "property uchar red\nproperty uchar green\nproperty uchar blue\n"
      << "element face " << mesh.triangles.size() << "\n"
      << "property list uchar int vertex_indices\nend_header\n";
  std::string buf;
  buf.reserve(mesh.positions.size() * 15 + mesh.triangles.size() * 13);
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    for (float x : mesh.positions[v]) Put(&buf, x);
    for (float ch : mesh.colours[v]) Put(&buf, ToByte(ch));
  }
  for (const auto& t : mesh.triangles) {
    Put(&buf, uint8_t{3});
    for (uint32_t i : t) Put(&buf, static_cast<int32_t>(i));
  }
  out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
}

void WriteObj(std::ostream& out, const Mesh& mesh) {
  CheckMesh(mesh);
  out << "# PERF mesh: " << mesh.positions.size() << " vertices, " << mesh.triangles.size() << " triangles\n"
      << "# positions in world units of the source frame; vertex colours as `v x y z r g b`, sRGB in [0, 1]\n"
      << "# (the extension read by Blender's OBJ importer and MeshLab)\n";
  char line[160];
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    const auto& p = mesh.positions[v];
    const auto& c = mesh.colours[v];
    // %.9g: floats round-trip exactly; colours to 1e-6.
    std::snprintf(line, sizeof line, "v %.9g %.9g %.9g %.6f %.6f %.6f\n", p[0], p[1], p[2], c[0], c[1], c[2]);
    out << line;
  }
  for (const auto& t : mesh.triangles) out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
}

// The GLB container: the JSON chunk, then the binary one (nv, nt: for the message when too large).
static void WriteGlbChunks(std::ostream& out, const nlohmann::json& doc, std::string bin, size_t nv, size_t nt);

void WriteGlb(std::ostream& out, const Mesh& mesh) {
  using nlohmann::json;
  CheckMesh(mesh);
  // Binary chunk: positions, linear colours, indices; each a multiple of 4 bytes.
  const size_t nv = mesh.positions.size(), nt = mesh.triangles.size();
  std::string bin;
  bin.reserve(24 * nv + 12 * nt);
  std::array<float, 3> lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  for (const auto& p : mesh.positions) {
    for (int a = 0; a < 3; ++a) {
      Put(&bin, p[a]);
      lo[a] = std::min(lo[a], p[a]);
      hi[a] = std::max(hi[a], p[a]);
    }
  }
  for (const auto& c : mesh.colours) {
    for (float ch : c) Put(&bin, static_cast<float>(SrgbToLinear(std::clamp(ch, 0.f, 1.f))));
  }
  for (const auto& t : mesh.triangles) {
    for (uint32_t i : t) Put(&bin, i);
  }

  json doc;
  doc["asset"] = {{"version", "2.0"}, {"generator", "PERF"}};
  doc["scene"] = 0;
  doc["scenes"] = json::array({{{"nodes", {0}}}});
  json node = {{"name", "perf_mesh"}};
  if (nt > 0) {
    // glTF forbids empty buffers and accessors: an empty mesh is a scene with one empty node.
    node["mesh"] = 0;
    constexpr int kFloat = 5126, kUnsignedInt = 5125, kArrayBuffer = 34962, kElementArrayBuffer = 34963;
    doc["buffers"] = json::array({{{"byteLength", bin.size()}}});
    doc["bufferViews"] = json::array({
        {{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 12 * nv}, {"target", kArrayBuffer}},
        {{"buffer", 0}, {"byteOffset", 12 * nv}, {"byteLength", 12 * nv}, {"target", kArrayBuffer}},
        {{"buffer", 0}, {"byteOffset", 24 * nv}, {"byteLength", 12 * nt}, {"target", kElementArrayBuffer}},
    });
    doc["accessors"] = json::array({
        {{"bufferView", 0}, {"componentType", kFloat}, {"count", nv}, {"type", "VEC3"}, {"min", lo}, {"max", hi}},
        {{"bufferView", 1}, {"componentType", kFloat}, {"count", nv}, {"type", "VEC3"}},
        {{"bufferView", 2}, {"componentType", kUnsignedInt}, {"count", 3 * nt}, {"type", "SCALAR"}},
    });
    doc["materials"] = json::array({{{"name", "perf_vertex_colour"},
                                     {"pbrMetallicRoughness",
                                      {{"baseColorFactor", {1, 1, 1, 1}}, {"metallicFactor", 0}, {"roughnessFactor", 1}}}}});
    doc["meshes"] = json::array({{{"name", "perf_mesh"},
                                  {"primitives",
                                   json::array({{{"attributes", {{"POSITION", 0}, {"COLOR_0", 1}}},
                                                 {"indices", 2},
                                                 {"material", 0},
                                                 {"mode", 4}}})}}});
  }
  doc["nodes"] = json::array({node});
  WriteGlbChunks(out, doc, std::move(bin), nv, nt);
}

static void WriteGlbChunks(std::ostream& out, const nlohmann::json& doc, std::string bin, size_t nv, size_t nt) {
  std::string json_text = doc.dump();
  json_text.resize((json_text.size() + 3) / 4 * 4, ' ');  // JSON chunk padded with spaces
  bin.resize((bin.size() + 3) / 4 * 4, '\0');               // BIN chunk padded with zeros
  const bool has_bin = !bin.empty();
  const uint64_t total = 12 + 8 + json_text.size() + (has_bin ? 8 + bin.size() : 0);
  if (total > 0xffffffffull) {
    throw ResourceError(StrCat("the mesh (", nv, " vertices, ", nt, " triangles) needs ", total,
                               " bytes, more than a GLB file can hold (4 GiB)"));
  }
  std::string head;
  Put(&head, uint32_t{0x46546C67});  // "glTF"
  Put(&head, uint32_t{2});
  Put(&head, static_cast<uint32_t>(total));
  Put(&head, static_cast<uint32_t>(json_text.size()));
  Put(&head, uint32_t{0x4E4F534A});  // "JSON"
  out.write(head.data(), static_cast<std::streamsize>(head.size()));
  out.write(json_text.data(), static_cast<std::streamsize>(json_text.size()));
  if (has_bin) {
    std::string bin_head;
    Put(&bin_head, static_cast<uint32_t>(bin.size()));
    Put(&bin_head, uint32_t{0x004E4942});  // "BIN\0"
    out.write(bin_head.data(), static_cast<std::streamsize>(bin_head.size()));
    out.write(bin.data(), static_cast<std::streamsize>(bin.size()));
  }
}

void WriteGlb(std::ostream& out, const Mesh& mesh, const std::vector<std::array<float, 2>>& uvs,
              const std::string& png) {
  using nlohmann::json;
  CheckMesh(mesh);
  const size_t nt = mesh.triangles.size(), nv = 3 * nt;  // a vertex per triangle corner
  PERF_CHECK(uvs.size() == nv);
  if (nt == 0 || png.empty()) return WriteGlb(out, mesh);
  // Binary chunk: positions, texture coordinates, the PNG; each a multiple of 4 bytes.
  std::string bin;
  bin.reserve(20 * nv + png.size() + 4);
  std::array<float, 3> lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  for (const auto& t : mesh.triangles) {
    for (uint32_t v : t) {
      for (int a = 0; a < 3; ++a) {
        Put(&bin, mesh.positions[v][a]);
        lo[a] = std::min(lo[a], mesh.positions[v][a]);
        hi[a] = std::max(hi[a], mesh.positions[v][a]);
      }
    }
  }
  for (const auto& uv : uvs) {
    Put(&bin, uv[0]);
    Put(&bin, uv[1]);
  }
  const size_t png_at = bin.size();
  bin += png;
  constexpr int kFloat = 5126, kArrayBuffer = 34962;
  json doc;
  doc["asset"] = {{"version", "2.0"}, {"generator", "PERF"}};
  doc["scene"] = 0;
  doc["scenes"] = json::array({{{"nodes", {0}}}});
  doc["nodes"] = json::array({{{"name", "perf_mesh"}, {"mesh", 0}}});
  doc["buffers"] = json::array({{{"byteLength", (bin.size() + 3) / 4 * 4}}});
  doc["bufferViews"] = json::array({
      {{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 12 * nv}, {"target", kArrayBuffer}},
      {{"buffer", 0}, {"byteOffset", 12 * nv}, {"byteLength", 8 * nv}, {"target", kArrayBuffer}},
      {{"buffer", 0}, {"byteOffset", png_at}, {"byteLength", png.size()}},
  });
  doc["accessors"] = json::array({
      {{"bufferView", 0}, {"componentType", kFloat}, {"count", nv}, {"type", "VEC3"}, {"min", lo}, {"max", hi}},
      {{"bufferView", 1}, {"componentType", kFloat}, {"count", nv}, {"type", "VEC2"}},
  });
  doc["images"] = json::array({{{"bufferView", 2}, {"mimeType", "image/png"}, {"name", "perf_texture"}}});
  constexpr int kLinear = 9729, kClampToEdge = 33071;
  doc["samplers"] = json::array({{{"magFilter", kLinear}, {"minFilter", kLinear}, {"wrapS", kClampToEdge},
                                  {"wrapT", kClampToEdge}}});
  doc["textures"] = json::array({{{"source", 0}, {"sampler", 0}}});
  doc["materials"] = json::array({{{"name", "perf_texture"},
                                   {"pbrMetallicRoughness",
                                    {{"baseColorTexture", {{"index", 0}}}, {"metallicFactor", 0}, {"roughnessFactor", 1}}}}});
  doc["meshes"] = json::array({{{"name", "perf_mesh"},
                                {"primitives", json::array({{{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}},
                                                             {"material", 0},
                                                             {"mode", 4}}})}}});
  WriteGlbChunks(out, doc, std::move(bin), nv, nt);
}

void WritePly(const fs::path& path, const Mesh& mesh) {
  WriteStreamAtomically(path, [&](std::ostream& out) { WritePly(out, mesh); });
}
void WriteObj(const fs::path& path, const Mesh& mesh) {
  WriteStreamAtomically(path, [&](std::ostream& out) { WriteObj(out, mesh); });
}
void WriteGlb(const fs::path& path, const Mesh& mesh) {
  WriteStreamAtomically(path, [&](std::ostream& out) { WriteGlb(out, mesh); });
}

}  // namespace perf::exporter
