// Random rays for the double-precision per-ray tests (ray_math_test, sparse_march_test).
#pragma once

#include <random>

#include "recon_cuda/core/ray_math.h"

namespace perf::recon::test {

inline Vec3<double> Cross(Vec3<double> a, Vec3<double> b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

// A camera `distance` from the box centre looking at a point within `aim` of it (per axis), and a
// random point of a random pixel of its 64 x 48 image; the ray in the frame of an n^3 grid.
inline BoxRay<double> RandomCameraRay(const BoxFrame<double>& box, int n, std::mt19937& rng, double distance,
                                      double aim = 0.3) {
  using V3 = Vec3<double>;
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> u(0, 1), off(-aim, aim);
  const V3 pos = box.center + Normalized(V3{g(rng), g(rng), g(rng)}) * distance;
  const V3 z = Normalized(box.center + V3{off(rng), off(rng), off(rng)} - pos);
  const V3 xa = Normalized(Cross(z, V3{0.2, 1.0, 0.1}));
  const V3 ya = Cross(z, xa);
  PinholeCamera<double> cam{50, 50, 32, 24, {xa.x, ya.x, z.x, pos.x, xa.y, ya.y, z.y, pos.y, xa.z, ya.z, z.z, pos.z}};
  V3 o, d;
  PixelRay(cam, static_cast<int>(u(rng) * 64), static_cast<int>(u(rng) * 48), u(rng), u(rng), &o, &d);
  return ToBoxRay(box, n, o, d);
}

}  // namespace perf::recon::test
