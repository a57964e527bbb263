// Hand-built checkpoints for the export tests: spheres of density in a box that is rotated,
// off-centre and anisotropic, so that every part of the index-to-world map is exercised.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <functional>

#include "recon_cuda/data/checkpoint.h"

namespace perf::exporter::test {

using Vec3 = std::array<double, 3>;

// world_from_box: a rotation of 0.7 rad about (1, 2, 3) / |(1, 2, 3)| (Rodrigues), row-major.
inline std::array<double, 9> TestRotation() {
  const double len = std::sqrt(14.0), u[3] = {1 / len, 2 / len, 3 / len}, t = 0.7;
  const double c = std::cos(t), s = std::sin(t);
  return {c + u[0] * u[0] * (1 - c),        u[0] * u[1] * (1 - c) - u[2] * s, u[0] * u[2] * (1 - c) + u[1] * s,
          u[1] * u[0] * (1 - c) + u[2] * s, c + u[1] * u[1] * (1 - c),        u[1] * u[2] * (1 - c) - u[0] * s,
          u[2] * u[0] * (1 - c) - u[1] * s, u[2] * u[1] * (1 - c) + u[0] * s, c + u[2] * u[2] * (1 - c)};
}

// An empty n^3 checkpoint in the test box: centre (1.5, -2, 0.75), size (2, 3, 2.5), rotated.
inline recon::Checkpoint EmptyCheckpoint(int n) {
  recon::Checkpoint c;
  c.level = 2;
  c.shape = {n, 1, 0};
  const double centre[3] = {1.5, -2.0, 0.75}, size[3] = {2.0, 3.0, 2.5};
  const std::array<double, 9> r = TestRotation();
  for (int a = 0; a < 3; ++a) {
    c.placement.box_center[a] = centre[a];
    c.placement.box_size[a] = size[a];
  }
  for (int i = 0; i < 9; ++i) c.placement.box_rotation[i] = r[i];
  c.params.assign(static_cast<size_t>(c.shape.ParamCount()), 0.f);
  return c;
}

// Box-local centre of cell (i, j, k).
inline Vec3 CellLocal(const recon::Checkpoint& c, int i, int j, int k) {
  const int idx[3] = {i, j, k};
  Vec3 p;
  for (int a = 0; a < 3; ++a) {
    const double s = c.placement.box_size[a];
    p[a] = (idx[a] + 0.5) * s / c.shape.n - s / 2;
  }
  return p;
}

inline Vec3 LocalToWorld(const recon::Checkpoint& c, const Vec3& p) {
  const double* r = c.placement.box_rotation;
  Vec3 w;
  for (int a = 0; a < 3; ++a) w[a] = c.placement.box_center[a] + r[3 * a] * p[0] + r[3 * a + 1] * p[1] + r[3 * a + 2] * p[2];
  return w;
}

inline Vec3 WorldToLocal(const recon::Checkpoint& c, const Vec3& w) {
  const double* r = c.placement.box_rotation;
  const Vec3 d{w[0] - c.placement.box_center[0], w[1] - c.placement.box_center[1], w[2] - c.placement.box_center[2]};
  return {r[0] * d[0] + r[3] * d[1] + r[6] * d[2], r[1] * d[0] + r[4] * d[1] + r[7] * d[2],
          r[2] * d[0] + r[5] * d[1] + r[8] * d[2]};
}

inline double Distance(const Vec3& a, const Vec3& b) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
}

// The shortest cell side (the exporters' opacity length).
inline double Length(const recon::Checkpoint& c) {
  const double* s = c.placement.box_size;
  return std::fmin(s[0], std::fmin(s[1], s[2])) / c.shape.n;
}

// Raises every cell's opacity (across Length) to `opacity` at its world centre, and sets its
// colour where it did (so several shapes add up as their union); leaves other cells as they are.
inline void Paint(recon::Checkpoint* c, const std::function<double(const Vec3&)>& opacity,
                  const std::array<float, 3>& rgb) {
  const int n = c->shape.n;
  const double len = Length(*c);
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const double a = std::fmin(opacity(LocalToWorld(*c, CellLocal(*c, i, j, k))), 1 - 1e-7);
        const int64_t cell = recon::GridCell(n, i, j, k);
        const double old = -std::expm1(-static_cast<double>(c->params[recon::GridParam(cell, 3)]) * len);
        if (!(a > 0) || a <= old) continue;
        c->params[recon::GridParam(cell, 3)] = static_cast<float>(-std::log1p(-a) / len);
        for (int ch = 0; ch < 3; ++ch) c->params[recon::GridParam(cell, ch)] = rgb[ch];
      }
    }
  }
}

// A smooth sphere: opacity 1 / (1 + exp((d - radius) / width)), 0.5 exactly at the radius, so
// the iso-surface of the trilinear field is the sphere up to O(cell^2) terms.
inline std::function<double(const Vec3&)> SmoothSphere(const Vec3& centre, double radius, double width) {
  return [=](const Vec3& p) { return 1 / (1 + std::exp((Distance(p, centre) - radius) / width)); };
}

// A hard sphere: opaque inside, empty (sigma 0) outside.
inline std::function<double(const Vec3&)> HardSphere(const Vec3& centre, double radius) {
  return [=](const Vec3& p) { return Distance(p, centre) < radius ? 1.0 : 0.0; };
}

// Gives every cell a colour that is not `rgb`, as the solver leaves empty cells: any colour.
inline void FillColours(recon::Checkpoint* c, const std::array<float, 3>& rgb) {
  const int64_t cells = static_cast<int64_t>(c->shape.n) * c->shape.n * c->shape.n;
  for (int64_t cell = 0; cell < cells; ++cell) {
    for (int ch = 0; ch < 3; ++ch) c->params[recon::GridParam(cell, ch)] = rgb[ch];
  }
}

}  // namespace perf::exporter::test
