#include "export/mesh_texture.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <ostream>

#include "common/errors.h"

namespace perf::exporter {
namespace {

constexpr const char* kMaterial = "perf_texture";

uint8_t ToByte(float v) { return static_cast<uint8_t>(std::lround(255 * std::clamp(v, 0.f, 1.f))); }

}  // namespace

TexturedMesh BakeTexture(const Mesh& mesh, const ColourSampler& colours, int max_side) {
  TexturedMesh t;
  t.mesh = mesh;
  const int64_t n = static_cast<int64_t>(mesh.triangles.size());
  if (n == 0) return t;
  const int per_row = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(n))));
  t.cell = std::clamp(max_side / per_row, 4, 32);
  const int rows = static_cast<int>((n + per_row - 1) / per_row);
  t.width = per_row * t.cell;
  t.height = rows * t.cell;
  t.rgb.assign(static_cast<size_t>(t.width) * t.height * 3, 0);
  t.uvs.resize(static_cast<size_t>(3 * n));
  // The triangle's corners in its cell, in texels from the cell's corner: one texel in from the
  // edges, the right angle at corner 0.
  const double lo = 1.0, hi = t.cell - 1.0, side = hi - lo;
  tbb::parallel_for(int64_t{0}, n, [&](int64_t k) {
    const int x0 = static_cast<int>(k % per_row) * t.cell, y0 = static_cast<int>(k / per_row) * t.cell;
    const auto& tri = mesh.triangles[static_cast<size_t>(k)];
    const std::array<double, 2> corner[3] = {{lo, lo}, {hi, lo}, {lo, hi}};
    for (int c = 0; c < 3; ++c) {
      t.uvs[static_cast<size_t>(3 * k + c)] = {static_cast<float>((x0 + corner[c][0]) / t.width),
                                               static_cast<float>((y0 + corner[c][1]) / t.height)};
    }
    const auto& p0 = mesh.positions[tri[0]];
    const auto& p1 = mesh.positions[tri[1]];
    const auto& p2 = mesh.positions[tri[2]];
    for (int j = 0; j < t.cell; ++j) {
      for (int i = 0; i < t.cell; ++i) {
        // The texel centre's barycentric weights, clamped onto the triangle (the padding).
        double u = std::max(0.0, (i + 0.5 - lo) / side), v = std::max(0.0, (j + 0.5 - lo) / side);
        if (u + v > 1) {
          const double s = u + v;
          u /= s, v /= s;
        }
        const double w = 1 - u - v;
        std::array<double, 3> point;
        for (int a = 0; a < 3; ++a) point[a] = w * p0[a] + u * p1[a] + v * p2[a];
        bool near_opaque = false;
        std::array<float, 3> rgb = colours.At(point, &near_opaque);
        if (!near_opaque) {  // a simplified triangle's point off the surface: its corners' colours
          for (int ch = 0; ch < 3; ++ch) {
            rgb[ch] = static_cast<float>(w * mesh.colours[tri[0]][ch] + u * mesh.colours[tri[1]][ch] +
                                         v * mesh.colours[tri[2]][ch]);
          }
        }
        uint8_t* texel = &t.rgb[3 * (static_cast<size_t>(y0 + j) * t.width + x0 + i)];
        for (int ch = 0; ch < 3; ++ch) texel[ch] = ToByte(rgb[ch]);
      }
    }
  });
  return t;
}

std::string TexturePng(const TexturedMesh& textured) {
  if (textured.width == 0) return {};
  cv::Mat bgr(textured.height, textured.width, CV_8UC3);
  for (int y = 0; y < textured.height; ++y) {
    for (int x = 0; x < textured.width; ++x) {
      const uint8_t* p = &textured.rgb[3 * (static_cast<size_t>(y) * textured.width + x)];
      bgr.at<cv::Vec3b>(y, x) = cv::Vec3b(p[2], p[1], p[0]);
    }
  }
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", bgr, bytes)) throw InternalError("the mesh texture could not be encoded as PNG");
  return std::string(bytes.begin(), bytes.end());
}

void WriteMtl(std::ostream& out, const std::string& png_name) {
  out << "# PERF mesh material: the baked colour texture\nnewmtl " << kMaterial
      << "\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\nmap_Kd " << png_name << "\n";
}

void WriteTexturedObj(std::ostream& out, const TexturedMesh& textured, const std::string& mtl_name) {
  const Mesh& mesh = textured.mesh;
  char line[160];
  out << "# PERF mesh: positions in world units of the source frame; vertex colours as `v x y z r g b` "
         "(sRGB in [0, 1]) and a baked texture (" << mtl_name << ")\n";
  out << "mtllib " << mtl_name << "\nusemtl " << kMaterial << "\n";
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    const auto& p = mesh.positions[v];
    const auto& c = mesh.colours[v];
    std::snprintf(line, sizeof(line), "v %.9g %.9g %.9g %.6f %.6f %.6f\n", p[0], p[1], p[2], c[0], c[1], c[2]);
    out << line;
  }
  for (const auto& uv : textured.uvs) {
    std::snprintf(line, sizeof(line), "vt %.9g %.9g\n", uv[0], 1 - uv[1]);  // OBJ's v points up
    out << line;
  }
  for (size_t k = 0; k < mesh.triangles.size(); ++k) {
    const auto& t = mesh.triangles[k];
    std::snprintf(line, sizeof(line), "f %u/%zu %u/%zu %u/%zu\n", t[0] + 1, 3 * k + 1, t[1] + 1, 3 * k + 2, t[2] + 1,
                  3 * k + 3);
    out << line;
  }
}

}  // namespace perf::exporter
