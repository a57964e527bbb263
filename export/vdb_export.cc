#include "export/vdb_export.h"

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>

#include "common/atomic_file.h"
#include "common/errors.h"

namespace perf::exporter {

namespace fs = std::filesystem;

void CheckExportable(const recon::Checkpoint& c) {
  const int n = c.shape.n;
  if (n < 1) throw InputError("checkpoint", "n", StrCat(n), "the grid has no cells");
  if (static_cast<int64_t>(c.params.size()) < c.shape.GridParamCount()) {
    throw InputError("checkpoint", "parameters", StrCat(c.params.size()),
                     StrCat("fewer than the ", c.shape.GridParamCount(), " values of its ", n, "^3 grid"));
  }
  const double* s = c.placement.box_size;
  if (!(std::min({s[0], s[1], s[2]}) > 0) || !std::isfinite(s[0] + s[1] + s[2])) {
    throw InputError("checkpoint", "box size", StrCat(s[0], " ", s[1], " ", s[2]), "must be positive");
  }
}

double CellLength(const recon::Checkpoint& c) {
  const double* s = c.placement.box_size;
  return std::min({s[0], s[1], s[2]}) / c.shape.n;
}

double SrgbToLinear(double v) {
  return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

std::array<double, 12> WorldFromIndex(const recon::Checkpoint& c) {
  // world = centre + R (diag(s) (ijk + 0.5) - size / 2), s = size / n per axis.
  const recon::VolumePlacement& p = c.placement;
  std::array<double, 12> a{};
  double local0[3], s[3];
  for (int b = 0; b < 3; ++b) {
    s[b] = p.box_size[b] / c.shape.n;
    local0[b] = 0.5 * s[b] - 0.5 * p.box_size[b];
  }
  for (int r = 0; r < 3; ++r) {
    double t = p.box_center[r];
    for (int b = 0; b < 3; ++b) {
      a[4 * r + b] = p.box_rotation[3 * r + b] * s[b];
      t += p.box_rotation[3 * r + b] * local0[b];
    }
    a[4 * r + 3] = t;
  }
  return a;
}

namespace {

// OpenVDB multiplies row vectors on the left (world = index * M), with the translation in the
// last row: M is the transpose of our column-vector affine map.
openvdb::math::Transform::Ptr MakeTransform(const recon::Checkpoint& c) {
  const std::array<double, 12> a = WorldFromIndex(c);
  openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 4; ++col) m(col, r) = a[4 * r + col];
  }
  return openvdb::math::Transform::createLinearTransform(m);
}

}  // namespace

VdbStats WriteVdb(const recon::Checkpoint& c, const fs::path& path, const VdbOptions& options) {
  CheckExportable(c);
  openvdb::initialize();  // registers the grid types; idempotent and thread-safe
  const int n = c.shape.n;
  const double length = CellLength(c);
  // opacity >= min  <=>  sigma >= -log(1 - min) / length; min 0 keeps every sigma > 0.
  const double min_opacity = std::clamp(options.min_cell_opacity, 0.0, 1.0);
  const double min_sigma = min_opacity >= 1 ? INFINITY : -std::log1p(-min_opacity) / length;

  VdbStats stats;
  stats.total_voxels = static_cast<int64_t>(n) * n * n;
  for (int a = 0; a < 3; ++a) stats.voxel_size[a] = c.placement.box_size[a] / n;
  stats.density_grid = "density";
  stats.colour_grid = options.houdini_names ? "Cd" : "color";

  const openvdb::math::Transform::Ptr transform = MakeTransform(c);
  openvdb::FloatGrid::Ptr density = openvdb::FloatGrid::create(0.f);
  openvdb::Vec3SGrid::Ptr colour = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
  // The spherical harmonics beyond the constant, a grid per band (recon ray_types.h ShParam).
  const int bands = c.shape.sh_degree > 0 ? recon::ShBands(c.shape.sh_degree) : 0;
  std::vector<openvdb::Vec3SGrid::Ptr> sh;
  for (int k = 0; k < bands; ++k) sh.push_back(openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f)));
  {
    openvdb::FloatGrid::Accessor d = density->getAccessor();
    openvdb::Vec3SGrid::Accessor col = colour->getAccessor();
    std::vector<openvdb::Vec3SGrid::Accessor> sh_acc;
    for (const auto& g : sh) sh_acc.push_back(g->getAccessor());
    // The stored cells only: a sparse grid's 8^3 bricks land on OpenVDB's 8^3 leaves.
    recon::ForEachStoredCell(c.shape, [&](int i, int j, int k, int64_t cell) {
      const float sigma = c.params[recon::GridParam(cell, 3)];
      if (!(sigma > 0) || sigma < min_sigma) return;
      const openvdb::Coord xyz(i, j, k);
      d.setValue(xyz, sigma);
      openvdb::Vec3s rgb;
      for (int ch = 0; ch < 3; ++ch) {
        const double v = std::clamp(static_cast<double>(c.params[recon::GridParam(cell, ch)]), 0.0, 1.0);
        rgb[ch] = static_cast<float>(SrgbToLinear(v));
      }
      col.setValue(xyz, rgb);
      for (int k = 0; k < bands; ++k) {
        const int64_t at = recon::ShParam(c.shape.ShStart(), c.shape.sh_degree, cell, k, 0);
        sh_acc[k].setValue(xyz, openvdb::Vec3s(c.params[at], c.params[at + 1], c.params[at + 2]));
      }
      ++stats.active_voxels;
    });
  }
  density->setName(stats.density_grid);
  density->setGridClass(openvdb::GRID_FOG_VOLUME);
  density->setTransform(transform);
  density->insertMeta("units", openvdb::StringMetadata("extinction per world unit (1 / unit of the source frame)"));
  colour->setName(stats.colour_grid);
  colour->setVectorType(openvdb::VEC_INVARIANT);  // a colour, not a direction: no transform applies
  colour->setTransform(transform->copy());
  colour->insertMeta("colorspace", openvdb::StringMetadata("linear"));
  colour->insertMeta("units", openvdb::StringMetadata("linear Rec.709 RGB (sRGB primaries), converted from sRGB"));
  openvdb::GridPtrVec grids{density, colour};
  for (int k = 0; k < bands; ++k) {
    stats.sh_grids.push_back(StrCat("color_sh", k + 1));
    sh[k]->setName(stats.sh_grids.back());
    sh[k]->setVectorType(openvdb::VEC_INVARIANT);
    sh[k]->setTransform(transform->copy());
    sh[k]->insertMeta("units", openvdb::StringMetadata(
                                   "spherical-harmonic band of the colour before sRGB decoding: the sRGB colour seen "
                                   "along unit direction d (box frame) is the color grid's plus sum_k Y_k(d) color_shk"));
    sh[k]->insertMeta("perf_sh_band", openvdb::Int32Metadata(k + 1));
    grids.push_back(sh[k]);
  }
  for (const openvdb::GridBase::Ptr& g : grids) {
    g->setCreator("PERF");
    g->setSaveFloatAsHalf(options.half_float);
  }

  openvdb::MetaMap file_meta;
  file_meta.insertMeta("creator", openvdb::StringMetadata("PERF"));
  file_meta.insertMeta("colorspace", openvdb::StringMetadata("linear"));
  file_meta.insertMeta("units", openvdb::StringMetadata("world units of the source frame (COLMAP model or NeRF json)"));
  file_meta.insertMeta("perf_level", openvdb::Int32Metadata(c.level));
  file_meta.insertMeta("perf_grid_n", openvdb::Int32Metadata(n));
  file_meta.insertMeta("perf_min_cell_opacity", openvdb::DoubleMetadata(min_opacity));
  file_meta.insertMeta("perf_opacity_length", openvdb::DoubleMetadata(length));

  if (bands > 0) file_meta.insertMeta("perf_sh_degree", openvdb::Int32Metadata(c.shape.sh_degree));
  // Serialised in memory (the same format io::File writes, without its grid offsets) and written
  // with checked calls: io::File does not report a full disk.
  WriteStreamAtomically(path, [&](std::ostream& out) {
    try {
      openvdb::io::Stream(out).write(grids, file_meta);
    } catch (const openvdb::Exception& e) {
      throw IoError(path.string(), StrCat("cannot write the OpenVDB file: ", e.what()));
    }
  });
  std::error_code ec;
  stats.file_bytes = static_cast<int64_t>(fs::file_size(path, ec));
  return stats;
}

}  // namespace perf::exporter
