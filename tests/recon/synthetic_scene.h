// A known scene for convergence tests and benchmarks: a few coloured solids (opaque and partly
// transparent) in a grid, an environment of two shells, and cameras on a sphere around it. The
// photos are rendered by the forward model itself, averaging 4 x 4 sub-pixel rays per pixel
// (what the jittered training rays see on average), so the scene is exactly representable.
#pragma once

#include <cmath>
#include <vector>

#include "recon_cuda/core/ray_math.h"
#include "recon_cuda/solve/backend.h"
#include "tests/recon/recon_test_util.h"

namespace perf::recon::test {

struct SyntheticScene {
  VolumeShape shape;
  VolumeGeometry geometry;
  std::vector<float> truth;
  std::vector<PosedImage> train, test;

  // n: grid of the truth; views on a sphere of radius 3.5 (a Fibonacci lattice), every
  // `holdout`-th held out.
  SyntheticScene(int n, int m, int views, int size, int holdout) {
    shape = {n, m, 2};
    geometry.box = {{0, 0, 0}, {{1, 0, 0, 0, 1, 0, 0, 0, 1}}, {2, 2, 2}};
    geometry.shell_center = {0, 0, 0};
    geometry.shell_radii = {2.2f, 6.0f};
    truth.assign(shape.ParamCount(), 0.f);
    for (int k = 0; k < n; ++k) {
      for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
          // Cell centre in box coordinates [-1, 1]^3.
          const float x = 2 * (i + 0.5f) / n - 1, y = 2 * (j + 0.5f) / n - 1, z = 2 * (k + 0.5f) / n - 1;
          float c[3] = {0.5f, 0.5f, 0.5f}, sigma = 0;
          const float ds = std::sqrt((x + 0.3f) * (x + 0.3f) + y * y + (z + 0.1f) * (z + 0.1f));
          if (ds < 0.45f) {  // opaque red-orange sphere with a vertical gradient
            c[0] = 0.9f;
            c[1] = 0.3f + 0.3f * z;
            c[2] = 0.1f;
            sigma = 40;
          } else if (std::abs(x - 0.45f) < 0.25f && std::abs(y - 0.2f) < 0.3f && std::abs(z) < 0.35f) {
            c[0] = 0.1f;  // partly transparent green box
            c[1] = 0.8f;
            c[2] = 0.3f;
            sigma = 3;
          } else if (std::abs(y + 0.45f) < 0.15f && x * x + (z - 0.2f) * (z - 0.2f) < 0.35f * 0.35f) {
            c[0] = 0.2f;  // opaque blue disc
            c[1] = 0.3f;
            c[2] = 0.9f;
            sigma = 25;
          }
          const int64_t cell = GridCell(n, i, j, k);
          for (int ch = 0; ch < 3; ++ch) truth[GridParam(cell, ch)] = c[ch];
          truth[GridParam(cell, 3)] = sigma;
        }
      }
    }
    // Inner shell: clear; outer: a smooth sky (colour varies with direction).
    for (int face = 0; face < 6; ++face) {
      for (int v = 0; v < m; ++v) {
        for (int u = 0; u < m; ++u) {
          const Vec3<float> d = Normalized(CubeToDirection(CubeCoord<float>{face, (u + 0.5f) / m, (v + 0.5f) / m}));
          const int64_t inner = ShellParam(n, m, 0, face, u, v, 0), outer = ShellParam(n, m, 1, face, u, v, 0);
          for (int ch = 0; ch < 4; ++ch) truth[inner + ch] = ch < 3 ? 0.5f : 0.f;
          truth[outer + 0] = 0.75f + 0.2f * d.z;
          truth[outer + 1] = 0.7f + 0.1f * d.x;
          truth[outer + 2] = 0.8f - 0.1f * d.y;
          truth[outer + 3] = 1.f;
        }
      }
    }
    const VolumeView<float> vol = MakeView(shape, geometry, truth.data());
    const float golden = 2.39996323f;
    for (int v = 0; v < views; ++v) {
      const float zc = 1 - 2 * (v + 0.5f) / views, r = std::sqrt(1 - zc * zc);
      const Vec3<float> pos = Vec3<float>{r * std::cos(golden * v), r * std::sin(golden * v), zc} * 3.5f;
      PosedImage im;
      im.name = "view" + std::to_string(v);
      im.camera = LookAt(pos, {0, 0, 0}, 1.1f * size, size / 2.0f, size / 2.0f);
      im.image = Image(size, size, 3);
      const float zero[3] = {0, 0, 0};
      for (int y = 0; y < size; ++y) {
        for (int x = 0; x < size; ++x) {
          for (int s = 0; s < 16; ++s) {
            Vec3<float> o, d;
            PixelRay(im.camera, x, y, (s % 4 + 0.5f) / 4, (s / 4 + 0.5f) / 4, &o, &d);
            const BoxRay<float> ray = ToBoxRay(geometry.box, n, o, d);
            const RayOutput<float> out = Forward(vol, ray, Jitter{0, 0, false, false}, zero, 0.f);
            for (int ch = 0; ch < 3; ++ch) im.image.at(x, y, ch) += out.h[ch] / 16;
          }
        }
      }
      (v % holdout == 0 ? test : train).push_back(std::move(im));
    }
  }
};

}  // namespace perf::recon::test
