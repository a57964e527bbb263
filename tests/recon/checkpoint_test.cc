// Checkpoints: round trips through both overloads, and every kind of damage named clearly.
#include "recon_cuda/checkpoint.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "common/errors.h"
#include "tests/test_util.h"

namespace perf::recon {
namespace {

Checkpoint Sample() {
  Checkpoint c;
  c.level = 1;
  c.iterations = 12;
  c.solver = 1;
  c.shape = {4, 2, 2};
  c.placement.box_center[0] = 0.5;
  c.placement.box_size[2] = 3.25;
  c.placement.box_rotation[0] = 0;
  c.placement.box_rotation[1] = -1;
  c.placement.box_rotation[3] = 1;
  c.placement.box_rotation[4] = 0;
  c.placement.shell_center[1] = -0.75;
  c.placement.shell_radii = {2.0, 8.0};
  c.params.resize(c.shape.ParamCount());
  for (size_t i = 0; i < c.params.size(); ++i) c.params[i] = 0.001f * static_cast<float>(i);
  return c;
}

void ExpectEqual(const Checkpoint& a, const Checkpoint& b) {
  EXPECT_EQ(a.level, b.level);
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.solver, b.solver);
  EXPECT_EQ(a.shape, b.shape);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(a.placement.box_center[i], b.placement.box_center[i]);
    EXPECT_EQ(a.placement.box_size[i], b.placement.box_size[i]);
    EXPECT_EQ(a.placement.shell_center[i], b.placement.shell_center[i]);
  }
  for (int i = 0; i < 9; ++i) EXPECT_EQ(a.placement.box_rotation[i], b.placement.box_rotation[i]);
  EXPECT_EQ(a.placement.shell_radii, b.placement.shell_radii);
  EXPECT_EQ(a.params, b.params);
}

std::string Bytes(const Checkpoint& c) {
  std::ostringstream out;
  WriteCheckpoint(out, c);
  return out.str();
}

// The InputError's field when reading `bytes`, or "" if it reads.
std::string FieldOfError(const std::string& bytes) {
  std::istringstream in(bytes);
  try {
    ReadCheckpoint(in, "test.perfvol");
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("test.perfvol"), std::string::npos) << e.what();
    return e.field();
  }
  return "";
}

TEST(CheckpointTest, RoundTripsThroughStreamAndFile) {
  const Checkpoint c = Sample();
  const std::string bytes = Bytes(c);
  EXPECT_EQ(bytes.size(), 264 + 4 * c.params.size());
  std::istringstream in(bytes);
  ExpectEqual(ReadCheckpoint(in, "mem"), c);
  test::TempDir dir;
  const auto path = CheckpointPath(dir.path(), 1);
  EXPECT_EQ(path.filename(), "level_1.perfvol");
  EXPECT_EQ(LastCheckpointLevel(dir.path()), -1);
  std::filesystem::create_directories(dir.path() / "recon");
  WriteCheckpoint(path, c);
  ExpectEqual(ReadCheckpoint(path), c);
  WriteCheckpoint(CheckpointPath(dir.path(), 0), c);
  EXPECT_EQ(LastCheckpointLevel(dir.path()), 1);
  // Nothing but the checkpoints was left behind (no temporary files).
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path() / "recon")) files += e.is_regular_file();
  EXPECT_EQ(files, 2);
}

TEST(CheckpointTest, GeometryIsTheBoxLocalOne) {
  const VolumeGeometry g = GeometryOf(Sample());
  // R = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]; shell centre - box centre = (-0.5, -0.75, 0);
  // R^T d = (-0.75, 0.5, 0).
  EXPECT_NEAR(g.shell_center.x, -0.75, 1e-6);
  EXPECT_NEAR(g.shell_center.y, 0.5, 1e-6);
  EXPECT_EQ(g.num_shells(), 2);
  EXPECT_EQ(g.box.size.z, 3.25f);
}

TEST(CheckpointTest, DamageIsNamed) {
  const std::string good = Bytes(Sample());
  EXPECT_EQ(FieldOfError(good), "");
  EXPECT_EQ(FieldOfError(good.substr(0, 5)), "magic");
  EXPECT_EQ(FieldOfError("PERFVOX" + good.substr(7)), "magic");
  std::string v = good;
  v[8] = 9;  // version
  EXPECT_EQ(FieldOfError(v), "version");
  EXPECT_EQ(FieldOfError(good.substr(0, 100)), "box.rotation");
  EXPECT_EQ(FieldOfError(good.substr(0, good.size() - 4)), "parameters");
  std::string flipped = good;
  flipped[good.size() - 3] ^= 0x10;  // one bit of the last parameter
  EXPECT_EQ(FieldOfError(flipped), "checksum");
  EXPECT_EQ(FieldOfError(good + "x"), "size");
  std::string n = good;
  n[20] = 0;  // n = 0 (little-endian low byte; the rest is 0 already)
  EXPECT_EQ(FieldOfError(n), "n");
  std::string shells = good;
  shells[28] = 9;  // num_shells
  EXPECT_EQ(FieldOfError(shells), "num_shells");
}

TEST(CheckpointTest, MissingFileIsAnIoError) {
  test::TempDir dir;
  EXPECT_THROW(ReadCheckpoint(dir / "none.perfvol"), IoError);
}

}  // namespace
}  // namespace perf::recon
