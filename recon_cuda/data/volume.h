// The reconstructed volume on the host (DESIGN.md "Representation", "Hierarchy"): the dense
// grid and the environment shells in one flat parameter vector (layout in ray_types.h), the
// geometry that places them in the world, the random start of the coarsest level and the
// resampling from one level to the next.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "recon_cuda/core/param_ops.h"
#include "recon_cuda/core/ray_math.h"
#include "recon_cuda/core/smoothness.h"
#include "recon_cuda/data/brick_grid.h"

namespace perf {
struct Scene;
}

namespace perf::recon {

// Resolutions of one level, and which of its grid's bricks hold parameters.
struct VolumeShape {
  int n = 32;          // grid cells per axis
  int m = 32;          // texels per cube-map face side
  int num_shells = 0;  // <= kMaxShells
  std::shared_ptr<const BrickGrid> bricks;  // a brick-sparse grid (brick_grid.h); nullptr: dense
  int exposures = 0;   // training photos whose exposure is solved (ray_types.h ExposureParam); 0: none
  int sh_degree = 0;   // spherical harmonics of the grid's colour beyond the constant (ShParam); 0: none
  int poses = 0;       // training photos whose pose is refined (ray_types.h PoseParam); 0: none

  VolumeShape() = default;
  VolumeShape(int n_, int m_, int num_shells_, std::shared_ptr<const BrickGrid> bricks_ = nullptr, int exposures_ = 0,
              int sh_degree_ = 0, int poses_ = 0)
      : n(n_),
        m(m_),
        num_shells(num_shells_),
        bricks(std::move(bricks_)),
        exposures(exposures_),
        sh_degree(sh_degree_),
        poses(poses_) {}

  bool sparse() const { return bricks != nullptr; }
  // Where the shells start: 4 n^3, or 4 values per cell of the active bricks.
  int64_t GridParamCount() const { return bricks ? bricks->GridParams() : recon::GridParamCount(n); }
  // The shells' values, and the grid's spherical harmonics' for a grid of grid_params values.
  int64_t ShellParams() const { return 4 * static_cast<int64_t>(num_shells) * 6 * m * m; }
  int64_t ShParams(int64_t grid_params) const { return sh_degree > 0 ? ShStride(sh_degree) * (grid_params / 4) : 0; }
  // Where the grid's spherical harmonics start: after the shells.
  int64_t ShStart() const { return GridParamCount() + ShellParams(); }
  // Where the exposures start: after the spherical harmonics.
  int64_t ExposureStart() const { return ShStart() + ShParams(GridParamCount()); }
  // Where the pose corrections start: after the exposures.
  int64_t PoseStart() const { return ExposureStart() + static_cast<int64_t>(kExposureValues) * exposures; }
  // The parameter count with a grid of grid_params values (a checkpoint checks its count before
  // it has read its bricks).
  int64_t ParamCountFor(int64_t grid_params) const {
    return grid_params + ShellParams() + ShParams(grid_params) + static_cast<int64_t>(kExposureValues) * exposures +
           static_cast<int64_t>(kPoseValues) * poses;
  }
  int64_t ParamCount() const { return ParamCountFor(GridParamCount()); }
  ParamLayout Layout() const { return {GridParamCount(), ShStart(), ExposureStart(), PoseStart()}; }
  int64_t StoredCells() const { return GridParamCount() / 4; }
  int64_t ShellTexels() const { return ShellParams() / 4; }
  // The bricks holding parameters: the active ones, or every brick of a dense grid.
  int64_t StoredBricks() const { return bricks ? bricks->ActiveBricks() : BrickCount(n); }
  // The next level of the hierarchy: every resolution doubled, the grid dense, the same photos.
  VolumeShape Doubled() const { return {2 * n, 2 * m, num_shells, nullptr, exposures, sh_degree, poses}; }
  // The same resolutions with these bricks active (nullptr: dense).
  VolumeShape WithBricks(std::shared_ptr<const BrickGrid> b) const {
    return {n, m, num_shells, std::move(b), exposures, sh_degree, poses};
  }
  VolumeShape WithExposures(int photos) const { return {n, m, num_shells, bricks, photos, sh_degree, poses}; }
  VolumeShape WithShDegree(int degree) const { return {n, m, num_shells, bricks, exposures, degree, poses}; }
  VolumeShape WithPoses(int photos) const { return {n, m, num_shells, bricks, exposures, sh_degree, photos}; }
  VolumeShape WithShellResolution(int texels) const {
    return {n, texels, num_shells, bricks, exposures, sh_degree, poses};
  }
  bool operator==(const VolumeShape& o) const {
    return n == o.n && m == o.m && num_shells == o.num_shells && exposures == o.exposures &&
           sh_degree == o.sh_degree && poses == o.poses &&
           (bricks == o.bricks || (bricks && o.bricks && *bricks == *o.bricks));
  }
};

// Where the box and the shells are in the world, in double precision and the world frame, as
// scene.json and the checkpoints store it.
struct VolumePlacement {
  double box_center[3] = {0, 0, 0};
  double box_rotation[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // world_from_box, row-major
  double box_size[3] = {1, 1, 1};
  double shell_center[3] = {0, 0, 0};
  std::vector<double> shell_radii;

  static VolumePlacement FromScene(const Scene& scene);
};

// The placement as the ray math reads it (box frame, float); the same for every level.
struct VolumeGeometry {
  BoxFrame<float> box;
  Vec3<float> shell_center;  // box-local: R^T (shells.center - box.center)
  std::vector<float> shell_radii;

  // Throws InputError naming `source` and the field if the placement is unusable.
  static VolumeGeometry From(const VolumePlacement& placement, const std::string& source);
  static VolumeGeometry FromScene(const Scene& scene);
  int num_shells() const { return static_cast<int>(shell_radii.size()); }
};

// What a training photo sees: its camera and its image size in pixels.
struct ViewFrustum {
  PinholeCamera<float> camera{};
  int width = 0, height = 0;
};

// The view the ray math reads: params (and shape.bricks) must outlive it. A sparse shape's view
// points at the host's brick table (a device backend puts its own copy in its place).
VolumeView<float> MakeView(const VolumeShape& shape, const VolumeGeometry& geometry, const float* params);

struct InitOptions {
  uint32_t seed = 1;
  // Opacity of the box along its shortest side at the start: every cell's sigma is uniform in
  // [0, 2 s] with s chosen so that the mean optical depth across the box gives this opacity.
  // 0.99 (~0.13 per cell at 32^3, the paper's "low opacity"): carving a faint fog converges
  // better than growing surfaces from nothing, for GN and Adam alike (docs/tuning.md).
  double box_opacity = 0.99;
  double shell_opacity = 0.1;  // mean opacity of the inner shells' texels, uniform in [0, 2 a]
  // Shell texel colours: this colour (e.g. the photos' mean) when set (>= 0), else random.
  float shell_colour[3] = {-1, -1, -1};
};

// The stencil's view of the level's layout (smoothness.h), pointing at the host's brick tables
// (shape must outlive it; a device backend puts its own copies in their place).
SmoothnessLayout MakeSmoothnessLayout(const VolumeShape& shape);

// Random colours in [0, 1], low densities and shell opacities (the outermost shell's opacity is
// ignored by the ray math: it is always opaque).
std::vector<float> InitialParams(const VolumeShape& shape, const VolumeGeometry& geometry, const InitOptions& options);

// A fixed background (LevelProblem::fixed_shells): every shell texel opaque in `colour`; the
// grid is left as it is.
void SetBackgroundShells(const VolumeShape& shape, const float colour[3], std::span<float> params);

// Fills the `to` level from the `from` level (paper "Hierarchical formulation"): every new cell
// centre (texel centre) takes the trilinear (bilinear, per face) interpolation of the old
// values, linearly extrapolated over the quarter cell between the old outermost centres and the
// border, so constant and linear fields carry over exactly; then projected to the valid range.
std::vector<float> Resample(const VolumeShape& from, std::span<const float> params, const VolumeShape& to);

// The valid range (DESIGN.md "Gauss-Newton step"): sigma >= 0, colours and opacities in [0, 1].
void ProjectToValidRange(const VolumeShape& shape, std::span<float> params);

// The stored cell of grid cell (i, j, k): its index in the dense layout, or in the active bricks
// (-1 when its brick is inactive).
inline int64_t StoredCell(const VolumeShape& shape, int i, int j, int k) {
  return shape.bricks ? SparseCell(shape.bricks->slot.data(), shape.bricks->nb(), i, j, k) : GridCell(shape.n, i, j, k);
}

// Calls f(i, j, k, stored cell) for every stored cell (dense: all n^3, x fastest; sparse: brick by
// brick in slot order).
template <class F>
void ForEachStoredCell(const VolumeShape& shape, F&& f) {
  if (!shape.bricks) {
    for (int k = 0; k < shape.n; ++k)
      for (int j = 0; j < shape.n; ++j)
        for (int i = 0; i < shape.n; ++i) f(i, j, k, GridCell(shape.n, i, j, k));
    return;
  }
  shape.bricks->ForEachCell(f);
}

// What parameter i is (param_ops.h).
inline ParamKind KindOf(const VolumeShape& shape, int64_t i) { return KindOfParam(shape.Layout(), i); }

// "128^3 grid, 4 shells of 6 x 128^2 texels (33.8 M parameters)"; a sparse grid says
// "128^3 grid (310 of 4096 bricks), ...".
std::string DescribeShape(const VolumeShape& shape);

}  // namespace perf::recon
