#include "recon_cuda/data/occupancy.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "common/errors.h"

namespace perf::recon {

namespace {

// Whether the sphere (world centre c, radius r) may overlap the image of `view`: in front of the
// camera and within the image grown by a bound on the sphere's projected radius. The bound: over
// |d| <= r, (x + d_x) / (z + d_z) - x / z <= r (1 + |x| / z) / (z - r) for z > r.
bool MaySee(const ViewFrustum& view, const Vec3<double>& c, double r) {
  const float* m = view.camera.world_from_cam;  // [R | t], row-major; camera coordinates q = R^T (c - t)
  const double d[3] = {c.x - m[3], c.y - m[7], c.z - m[11]};
  double q[3];
  for (int a = 0; a < 3; ++a) q[a] = m[a] * d[0] + m[4 + a] * d[1] + m[8 + a] * d[2];
  if (q[2] <= -r) return false;  // behind the camera
  if (q[2] <= r) return true;    // around the camera's centre
  const double u = view.camera.fx * q[0] / q[2] + view.camera.cx, v = view.camera.fy * q[1] / q[2] + view.camera.cy;
  const double mu = view.camera.fx * r * (1 + std::abs(q[0]) / q[2]) / (q[2] - r);
  const double mv = view.camera.fy * r * (1 + std::abs(q[1]) / q[2]) / (q[2] - r);
  return u >= -mu && u <= view.width + mu && v >= -mv && v <= view.height + mv;
}

}  // namespace

std::vector<uint8_t> SeenBricks(int n, const VolumeGeometry& geometry, std::span<const ViewFrustum> views) {
  PERF_CHECK(n > 0 && n % kBrickSide == 0);
  const int nb = n / kBrickSide;
  std::vector<uint8_t> seen(static_cast<size_t>(BrickCount(n)), 0);
  const BoxFrame<float>& box = geometry.box;
  const double size[3] = {box.size.x, box.size.y, box.size.z};
  double brick[3], radius2 = 0;  // a brick's sides and its half diagonal squared
  for (int a = 0; a < 3; ++a) {
    brick[a] = size[a] * kBrickSide / n;
    radius2 += 0.25 * brick[a] * brick[a];
  }
  const double radius = std::sqrt(radius2);
  const float* r = box.world_from_box.m;
  for (int bk = 0; bk < nb; ++bk) {
    for (int bj = 0; bj < nb; ++bj) {
      for (int bi = 0; bi < nb; ++bi) {
        const double q[3] = {-size[0] / 2 + (bi + 0.5) * brick[0], -size[1] / 2 + (bj + 0.5) * brick[1],
                             -size[2] / 2 + (bk + 0.5) * brick[2]};
        const Vec3<double> c{box.center.x + r[0] * q[0] + r[1] * q[1] + r[2] * q[2],
                             box.center.y + r[3] * q[0] + r[4] * q[1] + r[5] * q[2],
                             box.center.z + r[6] * q[0] + r[7] * q[1] + r[8] * q[2]};
        uint8_t& s = seen[BrickOf(nb, bi, bj, bk)];
        for (size_t v = 0; v < views.size() && !s; ++v) s = MaySee(views[v], c, radius);
      }
    }
  }
  return seen;
}

std::shared_ptr<const BrickGrid> OccupiedBricks(const VolumeShape& shape, const VolumeGeometry& geometry,
                                                std::span<const float> x, int n_next, const OccupancyOptions& o,
                                                std::span<const ViewFrustum> views) {
  PERF_CHECK(static_cast<int64_t>(x.size()) == shape.ParamCount());
  PERF_CHECK(n_next > 0 && n_next % kBrickSide == 0);
  const int n = shape.n;
  const float side = std::min({geometry.box.size.x, geometry.box.size.y, geometry.box.size.z}) / static_cast<float>(n);
  // sigma * side >= -log(1 - min_opacity)
  const float min_sigma = -std::log1p(-std::clamp(o.min_opacity, 0.f, 0.999999f)) / side;

  // The occupied cells of the fitted level and their 3-D prefix sum, so that each brick asks "any
  // occupied cell in this box?" in O(1).
  const int64_t n1 = n + 1;
  std::vector<int32_t> sum(static_cast<size_t>(n1 * n1 * n1), 0);
  const auto at = [&](int i, int j, int k) -> int32_t& { return sum[(static_cast<int64_t>(k) * n1 + j) * n1 + i]; };
  std::vector<uint8_t> occupied(static_cast<size_t>(n) * n * n, 0);
  ForEachStoredCell(shape, [&](int i, int j, int k, int64_t cell) {
    occupied[GridCell(n, i, j, k)] = x[GridParam(cell, 3)] >= min_sigma;
  });
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        at(i + 1, j + 1, k + 1) = occupied[GridCell(n, i, j, k)] + at(i, j + 1, k + 1) + at(i + 1, j, k + 1) +
                                  at(i + 1, j + 1, k) - at(i, j, k + 1) - at(i, j + 1, k) - at(i + 1, j, k) +
                                  at(i, j, k);
  const auto count = [&](int i0, int j0, int k0, int i1, int j1, int k1) {  // cells [i0, i1) x ...
    return at(i1, j1, k1) - at(i0, j1, k1) - at(i1, j0, k1) - at(i1, j1, k0) + at(i0, j0, k1) + at(i0, j1, k0) +
           at(i1, j0, k0) - at(i0, j0, k0);
  };

  // Brick b of the next level spans next cells [8 b, 8 b + 8), fitted cells [8 b n / n_next,
  // (8 b + 8) n / n_next) (rounded outwards), grown by the dilation.
  const int nb = n_next / kBrickSide;
  const auto range = [&](int b, int* lo, int* hi) {
    *lo = std::clamp(static_cast<int>(std::floor(double(b) * kBrickSide * n / n_next)) - o.dilation, 0, n);
    *hi = std::clamp(static_cast<int>(std::ceil(double(b + 1) * kBrickSide * n / n_next)) + o.dilation, 0, n);
  };
  std::vector<uint8_t> active = views.empty() ? std::vector<uint8_t>(static_cast<size_t>(BrickCount(n_next)), 1)
                                             : SeenBricks(n_next, geometry, views);
  for (int bk = 0; bk < nb; ++bk) {
    for (int bj = 0; bj < nb; ++bj) {
      for (int bi = 0; bi < nb; ++bi) {
        int i0, i1, j0, j1, k0, k1;
        range(bi, &i0, &i1);
        range(bj, &j0, &j1);
        range(bk, &k0, &k1);
        uint8_t& a = active[BrickOf(nb, bi, bj, bk)];
        a = a && count(i0, j0, k0, i1, j1, k1) > 0;
      }
    }
  }
  return std::make_shared<const BrickGrid>(MakeBrickGrid(n_next, active));
}

}  // namespace perf::recon
