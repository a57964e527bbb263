// OpenVDB export: files read back with openvdb::io::File, checked against the checkpoint they
// came from (grid names and classes, the index-to-world transform of a rotated, off-centre,
// anisotropic box, voxel values, sparsity, half-float storage) and bad output paths.
#include "export/vdb_export.h"

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>

#include "common/errors.h"
#include "tests/export/synthetic_volume.h"
#include "tests/test_util.h"

namespace perf::exporter {
namespace {

namespace fs = std::filesystem;
using test::Vec3;

constexpr int kN = 32;
constexpr std::array<float, 3> kSrgb = {0.5f, 0.04f, 1.0f};
// The sRGB EOTF of kSrgb, computed by hand: ((0.5 + 0.055) / 1.055)^2.4, 0.04 / 12.92, 1.
constexpr double kLinear[3] = {0.214041140, 0.003095975, 1.0};

class VdbExportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    openvdb::initialize();
    checkpoint_ = test::EmptyCheckpoint(kN);
    centre_ = test::LocalToWorld(checkpoint_, {0.1, -0.2, 0.05});
    test::Paint(&checkpoint_, test::SmoothSphere(centre_, 0.6, 0.05), kSrgb);
  }

  struct Files {
    openvdb::FloatGrid::Ptr density;
    openvdb::Vec3SGrid::Ptr colour;
    openvdb::MetaMap::Ptr meta;
    std::vector<std::string> names;
  };
  static Files Read(const fs::path& path, const std::string& colour_name) {
    openvdb::io::File file(path.string());
    file.open();
    Files f;
    for (auto it = file.beginName(); it != file.endName(); ++it) f.names.push_back(it.gridName());
    std::sort(f.names.begin(), f.names.end());  // the file lists them in name order anyway
    f.meta = file.getMetadata();
    f.density = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("density"));
    if (file.hasGrid(colour_name)) f.colour = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid(colour_name));
    file.close();
    return f;
  }

  // Cells whose opacity across the shortest cell side reaches `min_opacity`.
  int64_t ExpectedActive(double min_opacity) const {
    int64_t count = 0;
    const double len = test::Length(checkpoint_);
    for (int64_t cell = 0; cell < int64_t{kN} * kN * kN; ++cell) {
      const double sigma = checkpoint_.params[recon::GridParam(cell, 3)];
      if (sigma > 0 && 1 - std::exp(-sigma * len) >= min_opacity) ++count;
    }
    return count;
  }

  float Sigma(int i, int j, int k) const { return checkpoint_.params[recon::GridParam(recon::GridCell(kN, i, j, k), 3)]; }

  recon::Checkpoint checkpoint_;
  Vec3 centre_;
  perf::test::TempDir dir_;
};

TEST_F(VdbExportTest, RoundTripGridsTransformAndValues) {
  const fs::path path = dir_ / "volume.vdb";
  const VdbStats stats = WriteVdb(checkpoint_, path, {});
  ASSERT_TRUE(fs::exists(path));
  EXPECT_EQ(stats.file_bytes, static_cast<int64_t>(fs::file_size(path)));
  EXPECT_EQ(stats.total_voxels, int64_t{kN} * kN * kN);
  EXPECT_EQ(stats.density_grid, "density");
  EXPECT_EQ(stats.colour_grid, "color");

  const Files f = Read(path, "color");
  EXPECT_EQ(f.names, (std::vector<std::string>{"color", "density"}));
  ASSERT_TRUE(f.density && f.colour);
  EXPECT_EQ(f.density->getGridClass(), openvdb::GRID_FOG_VOLUME);
  EXPECT_EQ(f.colour->getVectorType(), openvdb::VEC_INVARIANT);
  EXPECT_EQ(f.meta->metaValue<std::string>("colorspace"), "linear");
  EXPECT_EQ(f.colour->metaValue<std::string>("colorspace"), "linear");
  EXPECT_EQ(f.meta->metaValue<int32_t>("perf_grid_n"), kN);

  // Voxel size: the cell size along each box axis (anisotropic), in world units.
  const openvdb::Vec3d voxel = f.density->transform().voxelSize();
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(voxel[a], checkpoint_.placement.box_size[a] / kN, 1e-12) << a;
    EXPECT_EQ(stats.voxel_size[a], checkpoint_.placement.box_size[a] / kN);
  }
  EXPECT_TRUE(f.density->transform() == f.colour->transform());
  // Index (i, j, k) is the centre of cell (i, j, k), in world coordinates.
  for (const openvdb::Coord ijk : {openvdb::Coord(0, 0, 0), openvdb::Coord(kN - 1, 3, 17), openvdb::Coord(5, kN - 1, kN - 1)}) {
    const Vec3 expected = test::LocalToWorld(checkpoint_, test::CellLocal(checkpoint_, ijk.x(), ijk.y(), ijk.z()));
    const openvdb::Vec3d got = f.density->transform().indexToWorld(ijk);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(got[a], expected[a], 1e-12) << ijk << " axis " << a;
  }
  // The box corner (index -0.5) is box-local -size/2.
  const openvdb::Vec3d corner = f.density->transform().indexToWorld(openvdb::Vec3d(-0.5, -0.5, -0.5));
  const Vec3 corner_expected = test::LocalToWorld(checkpoint_, {-1.0, -1.5, -1.25});
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(corner[a], corner_expected[a], 1e-12);

  // Voxel values: sigma as written, colour linear.
  const openvdb::Coord middle(kN / 2, kN / 2 - 3, kN / 2);
  ASSERT_TRUE(f.density->tree().isValueOn(middle));
  EXPECT_EQ(f.density->tree().getValue(middle), Sigma(middle.x(), middle.y(), middle.z()));
  const openvdb::Vec3s rgb = f.colour->tree().getValue(middle);
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(rgb[ch], kLinear[ch], 1e-6) << ch;
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(SrgbToLinear(kSrgb[ch]), kLinear[ch], 1e-8) << ch;

  // Sparse: only cells at opacity >= 0.01; the box corner is empty (background 0).
  EXPECT_EQ(stats.active_voxels, ExpectedActive(0.01));
  EXPECT_EQ(static_cast<int64_t>(f.density->activeVoxelCount()), stats.active_voxels);
  EXPECT_EQ(static_cast<int64_t>(f.colour->activeVoxelCount()), stats.active_voxels);
  EXPECT_LT(stats.active_voxels, stats.total_voxels / 2);
  EXPECT_GT(stats.active_voxels, 0);
  EXPECT_FALSE(f.density->tree().isValueOn(openvdb::Coord(0, 0, 0)));
  EXPECT_EQ(f.density->tree().getValue(openvdb::Coord(0, 0, 0)), 0.f);
  EXPECT_EQ(f.density->background(), 0.f);
}

// A sparse checkpoint (only the bricks with cells the export writes) exports the same voxels as the dense
// one, its stored 8^3 bricks as OpenVDB's leaves; vdb_print (openvdb-tools) reads it.
TEST_F(VdbExportTest, SparseCheckpointWritesTheSameVoxels) {
  const int nb = kN / recon::kBrickSide;
  std::vector<uint8_t> active(nb * nb * nb, 0);
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i)
        if (1 - std::exp(-Sigma(i, j, k) * test::Length(checkpoint_)) >= 0.01) {  // what the export writes
          active[recon::BrickOf(nb, i / 8, j / 8, k / 8)] = 1;
        }
  recon::Checkpoint sparse = checkpoint_;
  auto bricks = std::make_shared<const recon::BrickGrid>(recon::MakeBrickGrid(kN, active));
  ASSERT_LT(bricks->ActiveBricks(), nb * nb * nb);
  sparse.shape = checkpoint_.shape.WithBricks(bricks);
  const int64_t grid = checkpoint_.shape.GridParamCount();
  sparse.params = recon::PackGrid<float>(*bricks, std::span<const float>(checkpoint_.params.data(), grid));
  sparse.params.insert(sparse.params.end(), checkpoint_.params.begin() + grid, checkpoint_.params.end());

  const VdbStats d = WriteVdb(checkpoint_, dir_ / "dense.vdb", {});
  const VdbStats s = WriteVdb(sparse, dir_ / "sparse.vdb", {});
  EXPECT_EQ(s.active_voxels, d.active_voxels);
  const Files fd = Read(dir_ / "dense.vdb", "color"), fs_ = Read(dir_ / "sparse.vdb", "color");
  ASSERT_TRUE(fd.density && fs_.density);
  EXPECT_EQ(fs_.density->activeVoxelCount(), fd.density->activeVoxelCount());
  EXPECT_LE(fs_.density->tree().leafCount(), static_cast<openvdb::Index32>(bricks->ActiveBricks()));
  for (auto it = fd.density->cbeginValueOn(); it; ++it) {
    ASSERT_TRUE(fs_.density->tree().isValueOn(it.getCoord())) << it.getCoord();
    EXPECT_EQ(fs_.density->tree().getValue(it.getCoord()), *it);
    EXPECT_EQ(fs_.colour->tree().getValue(it.getCoord()), fd.colour->tree().getValue(it.getCoord()));
  }
  if (std::system("command -v vdb_print > /dev/null 2>&1") != 0) GTEST_SKIP() << "vdb_print not installed";
  const auto r = perf::test::RunCommand("vdb_print -l " + (dir_ / "sparse.vdb").string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("density"), std::string::npos) << r.output;
  // "Number of active voxels:       11,459" (thousands separated) for the density grid.
  const size_t at = r.output.find("Number of active voxels:");
  ASSERT_NE(at, std::string::npos) << r.output;
  std::string digits;
  for (size_t i = at + 24; i < r.output.size() && r.output[i] != '\n'; ++i) {
    if (std::isdigit(static_cast<unsigned char>(r.output[i]))) digits += r.output[i];
  }
  EXPECT_EQ(digits, std::to_string(s.active_voxels)) << r.output;
}

TEST_F(VdbExportTest, ThresholdDecidesWhichCellsAreWritten) {
  const fs::path all = dir_ / "all.vdb", dense_only = dir_ / "dense.vdb";
  VdbOptions options;
  options.min_cell_opacity = 0;
  const VdbStats every = WriteVdb(checkpoint_, all, options);
  options.min_cell_opacity = 0.5;
  const VdbStats half = WriteVdb(checkpoint_, dense_only, options);
  EXPECT_EQ(every.active_voxels, ExpectedActive(1e-300));
  EXPECT_EQ(half.active_voxels, ExpectedActive(0.5));
  EXPECT_LT(half.active_voxels, every.active_voxels);
  // A cell just below 0.5 opacity is inactive in the thresholded file, active in the other.
  const Files f = Read(dense_only, "color");
  const double len = test::Length(checkpoint_);
  int checked = 0;
  for (int i = 0; i < kN && checked == 0; ++i) {
    const double a = 1 - std::exp(-Sigma(i, kN / 2, kN / 2) * len);
    if (a > 0.2 && a < 0.5) {
      EXPECT_FALSE(f.density->tree().isValueOn(openvdb::Coord(i, kN / 2, kN / 2)));
      EXPECT_TRUE(Read(all, "color").density->tree().isValueOn(openvdb::Coord(i, kN / 2, kN / 2)));
      ++checked;
    }
  }
  EXPECT_EQ(checked, 1);
}

TEST_F(VdbExportTest, HoudiniNamesTheColourGridCd) {
  const fs::path path = dir_ / "houdini.vdb";
  VdbOptions options;
  options.houdini_names = true;
  const VdbStats stats = WriteVdb(checkpoint_, path, options);
  EXPECT_EQ(stats.colour_grid, "Cd");
  const Files f = Read(path, "Cd");
  EXPECT_EQ(f.names, (std::vector<std::string>{"Cd", "density"}));
  ASSERT_TRUE(f.colour);
  EXPECT_EQ(static_cast<int64_t>(f.colour->activeVoxelCount()), stats.active_voxels);
}

// View-dependent colour (--sh-degree 1): a grid per band beyond the constant, on the same voxels
// as the colour, holding the checkpoint's coefficients.
TEST_F(VdbExportTest, SphericalHarmonicsGetAGridPerBand) {
  recon::Checkpoint c = checkpoint_;
  c.shape.sh_degree = 1;
  c.params.resize(c.shape.ParamCount(), 0.f);
  const int64_t cell = recon::GridCell(kN, kN / 2, kN / 2, kN / 2);
  ASSERT_GT(c.params[recon::GridParam(cell, 3)], 0.f);  // inside the painted sphere
  for (int k = 0; k < 3; ++k)
    for (int ch = 0; ch < 3; ++ch) c.params[recon::ShParam(c.shape.ShStart(), 1, cell, k, ch)] = 0.1f * (k + 1) - 0.05f * ch;
  const fs::path path = dir_ / "sh.vdb";
  const VdbStats stats = WriteVdb(c, path, {});
  EXPECT_EQ(stats.sh_grids, (std::vector<std::string>{"color_sh1", "color_sh2", "color_sh3"}));
  openvdb::io::File file(path.string());
  file.open();
  EXPECT_EQ(file.getMetadata()->metaValue<int32_t>("perf_sh_degree"), 1);
  for (int k = 0; k < 3; ++k) {
    const auto g = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid(stats.sh_grids[k]));
    ASSERT_TRUE(g);
    EXPECT_EQ(static_cast<int64_t>(g->activeVoxelCount()), stats.active_voxels);
    EXPECT_EQ(g->metaValue<int32_t>("perf_sh_band"), k + 1);
    const openvdb::Vec3s v = g->getConstAccessor().getValue(openvdb::Coord(kN / 2, kN / 2, kN / 2));
    for (int ch = 0; ch < 3; ++ch) EXPECT_FLOAT_EQ(v[ch], 0.1f * (k + 1) - 0.05f * ch) << k << " " << ch;
  }
  file.close();
  // Without spherical harmonics: no such grid.
  EXPECT_TRUE(WriteVdb(checkpoint_, dir_ / "plain.vdb", {}).sh_grids.empty());
}

TEST_F(VdbExportTest, HalfFloatReadsBackWithinHalfPrecision) {
  const fs::path full = dir_ / "full.vdb", half = dir_ / "half.vdb";
  const VdbStats full_stats = WriteVdb(checkpoint_, full, {});
  VdbOptions options;
  options.half_float = true;
  const VdbStats half_stats = WriteVdb(checkpoint_, half, options);
  EXPECT_LT(half_stats.file_bytes, full_stats.file_bytes);
  const Files f = Read(half, "color");
  EXPECT_TRUE(f.density->saveFloatAsHalf());
  EXPECT_EQ(static_cast<int64_t>(f.density->activeVoxelCount()), half_stats.active_voxels);
  int64_t compared = 0;
  for (auto it = f.density->cbeginValueOn(); it; ++it) {
    const openvdb::Coord ijk = it.getCoord();
    const float sigma = Sigma(ijk.x(), ijk.y(), ijk.z());
    // Half: 11 significant bits, relative error <= 2^-11.
    ASSERT_NEAR(*it, sigma, sigma * 4.9e-4) << ijk;
    const openvdb::Vec3s rgb = f.colour->tree().getValue(ijk);
    for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(rgb[ch], kLinear[ch], kLinear[ch] * 4.9e-4) << ijk;
    ++compared;
  }
  EXPECT_EQ(compared, half_stats.active_voxels);
}

TEST_F(VdbExportTest, UnwritablePathThrowsIoErrorAndLeavesNoFile) {
  const fs::path missing = dir_ / "no_such_folder" / "volume.vdb";
  try {
    WriteVdb(checkpoint_, missing, {});
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_EQ(e.path(), missing.string());
  }
  EXPECT_FALSE(fs::exists(missing));
  EXPECT_FALSE(fs::exists(missing.parent_path()));

  // A folder where the file should go: written to a temporary file, not moved into place.
  const fs::path occupied = dir_ / "occupied.vdb";
  fs::create_directories(occupied / "inside");
  EXPECT_THROW(WriteVdb(checkpoint_, occupied, {}), IoError);
  EXPECT_TRUE(fs::is_directory(occupied / "inside"));
  int entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir_.path())) ++entries;
  EXPECT_EQ(entries, 1) << "a temporary file was left behind";
}

TEST_F(VdbExportTest, BadCheckpointIsAnInputError) {
  recon::Checkpoint bad = checkpoint_;
  bad.params.resize(10);
  EXPECT_THROW(WriteVdb(bad, dir_ / "bad.vdb", {}), InputError);
  bad = checkpoint_;
  bad.placement.box_size[1] = 0;
  EXPECT_THROW(WriteVdb(bad, dir_ / "bad.vdb", {}), InputError);
  EXPECT_FALSE(fs::exists(dir_ / "bad.vdb"));
}

}  // namespace
}  // namespace perf::exporter
