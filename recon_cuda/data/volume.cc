#include "recon_cuda/data/volume.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>

#include "common/errors.h"

namespace perf::recon {

VolumeGeometry VolumeGeometry::From(const VolumePlacement& p, const std::string& source) {
  const double* s = p.box_size;
  if (!(std::min({s[0], s[1], s[2]}) > 0) || !std::isfinite(s[0] + s[1] + s[2])) {
    throw InputError(source, "box.size", StrCat(s[0], " ", s[1], " ", s[2]), "must be positive",
                     "re-run perf import, or pass --box-size");
  }
  const int k = static_cast<int>(p.shell_radii.size());
  if (k < 1 || k > kMaxShells) {
    throw InputError(source, "shells.radii", StrCat(k, " shells"),
                     StrCat("the reconstruction needs 1 to ", kMaxShells, " shells (the outermost ends every ray)"),
                     "re-run perf import with --shells N");
  }
  VolumeGeometry g;
  const double* r = p.box_rotation;
  g.box.center = {static_cast<float>(p.box_center[0]), static_cast<float>(p.box_center[1]),
                  static_cast<float>(p.box_center[2])};
  for (int i = 0; i < 9; ++i) g.box.world_from_box.m[i] = static_cast<float>(r[i]);
  g.box.size = {static_cast<float>(s[0]), static_cast<float>(s[1]), static_cast<float>(s[2])};
  // Box-local shell centre: R^T (shell centre - box centre), R row-major.
  double d[3], local[3];
  for (int a = 0; a < 3; ++a) d[a] = p.shell_center[a] - p.box_center[a];
  for (int a = 0; a < 3; ++a) local[a] = r[a] * d[0] + r[3 + a] * d[1] + r[6 + a] * d[2];
  g.shell_center = {static_cast<float>(local[0]), static_cast<float>(local[1]), static_cast<float>(local[2])};
  for (double radius : p.shell_radii) g.shell_radii.push_back(static_cast<float>(radius));
  return g;
}

VolumeView<float> MakeView(const VolumeShape& shape, const VolumeGeometry& geometry, const float* params) {
  PERF_CHECK(shape.num_shells == geometry.num_shells());
  VolumeView<float> v{};
  v.params = params;
  v.n = shape.n;
  v.size = geometry.box.size;
  v.num_shells = shape.num_shells;
  v.m = shape.m;
  v.shell_center = geometry.shell_center;
  v.sh_degree = shape.sh_degree;
  v.exposures = shape.exposures;
  v.poses = shape.poses;
  for (int k = 0; k < kMaxShells; ++k) v.shell_radii[k] = k < shape.num_shells ? geometry.shell_radii[k] : 0.f;
  if (shape.bricks) {
    PERF_CHECK(shape.bricks->n == shape.n);
    v.brick_slot = shape.bricks->slot.data();
    v.skip_blocks = shape.bricks->skip_blocks.data();
    v.active_bricks = shape.bricks->ActiveBricks();
  }
  return v;
}

SmoothnessLayout MakeSmoothnessLayout(const VolumeShape& shape) {
  SmoothnessLayout l;
  l.n = shape.n;
  l.m = shape.m;
  l.num_shells = shape.num_shells;
  l.params = shape.Layout();
  l.sh_degree = shape.sh_degree;
  if (shape.bricks) {
    l.slot = shape.bricks->slot.data();
    l.bricks = shape.bricks->bricks.data();
  }
  return l;
}

std::vector<float> InitialParams(const VolumeShape& shape, const VolumeGeometry& geometry, const InitOptions& options) {
  std::vector<float> x(static_cast<size_t>(shape.ParamCount()));
  std::mt19937 rng(options.seed);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  const double side = std::min({geometry.box.size.x, geometry.box.size.y, geometry.box.size.z});
  const double sigma_mean = -std::log(1.0 - std::clamp(options.box_opacity, 0.0, 1.0 - 1e-12)) / side;
  for (int64_t i = 0; i < shape.ParamCount(); ++i) {
    switch (KindOf(shape, i)) {
      case ParamKind::kGridDensity: x[i] = static_cast<float>(2 * sigma_mean) * unit(rng); break;
      case ParamKind::kShellOpacity: x[i] = static_cast<float>(2 * options.shell_opacity) * unit(rng); break;
      case ParamKind::kShellColour: {
        const float c = options.shell_colour[i % 4];
        x[i] = c >= 0 ? c : unit(rng);
        break;
      }
      case ParamKind::kExposureGain:
      case ParamKind::kExposureOffset: x[i] = 0; break;  // the identity
      case ParamKind::kGridSh: x[i] = 0; break;          // no view dependence
      case ParamKind::kPoseRotation:
      case ParamKind::kPoseCentre:
      case ParamKind::kPoseFocal: x[i] = 0; break;       // the imported poses
      case ParamKind::kGridColour: x[i] = unit(rng); break;
    }
  }
  ProjectToValidRange(shape, x);
  return x;
}

void SetBackgroundShells(const VolumeShape& shape, const float colour[3], std::span<float> params) {
  for (int64_t i = shape.GridParamCount(); i < shape.ShStart(); ++i) {
    params[i] = KindOf(shape, i) == ParamKind::kShellOpacity ? 1.f : colour[i % 4];
  }
}

namespace {

// One axis of the resampling: new sample i of `to` at old position (i + 0.5) from / to in old
// cell units; linear between the two nearest old centres, extrapolated beyond the outer ones.
struct Axis {
  int lo, hi;
  double f;  // weight of hi; may be < 0 or > 1 at the border (extrapolation)
};
std::vector<Axis> AxisWeights(int from, int to) {
  std::vector<Axis> a(to);
  for (int i = 0; i < to; ++i) {
    if (from == 1) {
      a[i] = {0, 0, 0.0};
      continue;
    }
    const double c = (i + 0.5) * from / to - 0.5;
    const int lo = std::clamp(static_cast<int>(std::floor(c)), 0, from - 2);
    a[i] = {lo, lo + 1, c - lo};
  }
  return a;
}

}  // namespace

std::vector<float> Resample(const VolumeShape& from, std::span<const float> params, const VolumeShape& to) {
  PERF_CHECK(static_cast<int64_t>(params.size()) == from.ParamCount());
  PERF_CHECK(from.num_shells == to.num_shells);
  std::vector<float> out(static_cast<size_t>(to.ParamCount()));
  // The photos' exposures and pose corrections carry over as they are (the same photos at every
  // level); a level that stops (starts) solving one kind drops it (starts it at the identity).
  if (from.exposures == to.exposures) {
    std::copy(params.begin() + from.ExposureStart(), params.begin() + from.PoseStart(), out.begin() + to.ExposureStart());
  }
  if (from.poses == to.poses) std::copy(params.begin() + from.PoseStart(), params.end(), out.begin() + to.PoseStart());
  const std::vector<Axis> g = AxisWeights(from.n, to.n);
  // The grid's spherical harmonics are interpolated as its values are (when both levels have them).
  const int sh = from.sh_degree == to.sh_degree && to.sh_degree > 0 ? ShStride(to.sh_degree) : 0;
  const int64_t from_sh = from.ShStart(), to_sh = to.ShStart();
  ForEachStoredCell(to, [&](int i, int j, int k, int64_t to_cell) {
    double v[4 + kMaxShStride] = {};
    for (int c = 0; c < 8; ++c) {
      const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
      const double w = (dx ? g[i].f : 1 - g[i].f) * (dy ? g[j].f : 1 - g[j].f) * (dz ? g[k].f : 1 - g[k].f);
      if (w == 0) continue;
      const int64_t cell = StoredCell(from, dx ? g[i].hi : g[i].lo, dy ? g[j].hi : g[j].lo, dz ? g[k].hi : g[k].lo);
      if (cell < 0) continue;  // an inactive brick: zeros
      for (int ch = 0; ch < 4; ++ch) v[ch] += w * params[GridParam(cell, ch)];
      for (int s = 0; s < sh; ++s) v[4 + s] += w * params[from_sh + sh * cell + s];
    }
    for (int ch = 0; ch < 4; ++ch) out[GridParam(to_cell, ch)] = static_cast<float>(v[ch]);
    for (int s = 0; s < sh; ++s) out[to_sh + sh * to_cell + s] = static_cast<float>(v[4 + s]);
  });
  const std::vector<Axis> t = AxisWeights(from.m, to.m);
  for (int s = 0; s < to.num_shells; ++s) {
    for (int face = 0; face < 6; ++face) {
      for (int v = 0; v < to.m; ++v) {
        for (int u = 0; u < to.m; ++u) {
          double acc[4] = {0, 0, 0, 0};
          for (int c = 0; c < 4; ++c) {
            const int du = c & 1, dv = c >> 1;
            const double w = (du ? t[u].f : 1 - t[u].f) * (dv ? t[v].f : 1 - t[v].f);
            if (w == 0) continue;
            const int64_t p = ShellParamAt(from.GridParamCount(), from.m, s, face, du ? t[u].hi : t[u].lo,
                                           dv ? t[v].hi : t[v].lo, 0);
            for (int ch = 0; ch < 4; ++ch) acc[ch] += w * params[p + ch];
          }
          const int64_t p = ShellParamAt(to.GridParamCount(), to.m, s, face, u, v, 0);
          for (int ch = 0; ch < 4; ++ch) out[p + ch] = static_cast<float>(acc[ch]);
        }
      }
    }
  }
  ProjectToValidRange(to, out);
  return out;
}

void ProjectToValidRange(const VolumeShape& shape, std::span<float> x) {
  PERF_CHECK(static_cast<int64_t>(x.size()) == shape.ParamCount());
  for (int64_t i = 0; i < static_cast<int64_t>(x.size()); ++i) x[i] = ProjectToValid(KindOf(shape, i), x[i]);
}

std::string DescribeShape(const VolumeShape& shape) {
  std::ostringstream s;
  s << shape.n << "^3 grid";
  if (shape.bricks) s << " (" << shape.bricks->ActiveBricks() << " of " << BrickCount(shape.n) << " bricks)";
  s << ", " << shape.num_shells << " shell" << (shape.num_shells == 1 ? "" : "s") << " of 6 x "
    << shape.m << "^2 texels (";
  const double p = static_cast<double>(shape.ParamCount());
  if (p >= 1e6) {
    s.precision(3);
    s << p / 1e6 << " M parameters)";
  } else {
    s << shape.ParamCount() << " parameters)";
  }
  if (shape.sh_degree > 0) s << ", spherical harmonics of degree " << shape.sh_degree;
  if (shape.exposures > 0) s << ", exposures of " << shape.exposures << " photos";
  if (shape.poses > 0) s << ", poses of " << shape.poses << " photos";
  return s.str();
}

}  // namespace perf::recon
