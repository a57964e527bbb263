// Checkpoints: round trips through both overloads, and every kind of damage named clearly.
#include "recon_cuda/data/checkpoint.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <streambuf>

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
  EXPECT_EQ(bytes.size(), 288 + 4 * c.params.size());
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

TEST(CheckpointTest, ExposuresTravelAndVersionTwoFilesReadWithout) {
  Checkpoint c = Sample();
  c.shape.exposures = 3;
  c.params.resize(c.shape.ParamCount());
  for (int k = 0; k < 3 * kExposureValues; ++k) c.params[c.shape.ExposureStart() + k] = 0.01f * (k % 4 == 3 ? 0 : k);
  const std::string bytes = Bytes(c);
  EXPECT_EQ(bytes.size(), 288 + 4 * c.params.size());
  std::istringstream in(bytes);
  const Checkpoint back = ReadCheckpoint(in, "mem");
  EXPECT_EQ(back.shape.exposures, 3);
  ExpectEqual(back, c);

  std::string negative = bytes;
  const int32_t minus = -2, four = 4, three = 3;
  std::memcpy(&negative[272], &minus, 4);
  EXPECT_EQ(FieldOfError(negative), "exposures");
  std::string more = bytes;  // the count no longer matches the parameters
  std::memcpy(&more[272], &four, 4);
  EXPECT_EQ(FieldOfError(more), "parameter count");
  std::string degree = bytes;
  std::memcpy(&degree[276], &three, 4);
  EXPECT_EQ(FieldOfError(degree), "sh_degree");

  // Spherical harmonics of degree 2 on the sparse and dense grids travel too.
  Checkpoint sh = c;
  sh.shape.sh_degree = 2;
  sh.params.resize(sh.shape.ParamCount());
  for (size_t i = 0; i < sh.params.size(); ++i) sh.params[i] = 0.5f - 0.001f * static_cast<float>(i % 1000);
  std::istringstream in_sh(Bytes(sh));
  ExpectEqual(ReadCheckpoint(in_sh, "sh"), sh);

  // Pose corrections travel too, and a bad count is named.
  Checkpoint posed = c;
  posed.shape.poses = 3;
  posed.params.resize(posed.shape.ParamCount());
  for (size_t i = 0; i < posed.params.size(); ++i) posed.params[i] = 0.25f - 0.0005f * static_cast<float>(i % 700);
  const std::string posed_bytes = Bytes(posed);
  std::istringstream in_posed(posed_bytes);
  ExpectEqual(ReadCheckpoint(in_posed, "posed"), posed);
  std::string bad_poses = posed_bytes;
  std::memcpy(&bad_poses[280], &minus, 4);
  EXPECT_EQ(FieldOfError(bad_poses), "poses");

  // A version 3 file: the same header without the pose count; it refines no poses.
  const Checkpoint plain = Sample();
  const std::string v4 = Bytes(plain);
  std::string v3 = v4.substr(0, 280) + v4.substr(288);
  const uint32_t three_v = 3, header3 = 280;
  std::memcpy(&v3[8], &three_v, 4);
  std::memcpy(&v3[12], &header3, 4);
  std::istringstream in3(v3);
  const Checkpoint old3 = ReadCheckpoint(in3, "v3");
  EXPECT_EQ(old3.shape.poses, 0);
  ExpectEqual(old3, plain);

  // A version 2 file: the same header without the exposure count; it has no exposures.
  std::string v2 = v3.substr(0, 272) + v3.substr(280);
  const uint32_t two = 2, header = 272;
  std::memcpy(&v2[8], &two, 4);
  std::memcpy(&v2[12], &header, 4);
  std::istringstream in2(v2);
  const Checkpoint old = ReadCheckpoint(in2, "v2");
  EXPECT_EQ(old.shape.exposures, 0);
  ExpectEqual(old, plain);
}

// The sample's 288-byte header claiming an n^3 grid and m^2 texels per face (two shells), with
// the matching parameter count, and no parameters after it.
std::string HugeHeader(int32_t n, int32_t m) {
  std::string h = Bytes(Sample()).substr(0, 288);
  std::memcpy(&h[20], &n, 4);
  std::memcpy(&h[24], &m, 4);
  const uint64_t count = static_cast<uint64_t>(ParamCount(n, m, 2));
  std::memcpy(&h[248], &count, 8);
  return h;
}

// A sparse 16^3 grid: 3 of its 8 bricks active.
Checkpoint SparseSample() {
  Checkpoint c = Sample();
  std::vector<uint8_t> active(8, 0);
  active[1] = active[4] = active[7] = 1;
  c.shape = VolumeShape{16, 2, 2}.WithBricks(std::make_shared<const BrickGrid>(MakeBrickGrid(16, active)));
  c.params.resize(c.shape.ParamCount());
  for (size_t i = 0; i < c.params.size(); ++i) c.params[i] = 0.001f * static_cast<float>(i);
  return c;
}

TEST(CheckpointTest, SparseGridsRoundTripAndVersion1StillReads) {
  const Checkpoint c = SparseSample();
  const std::string bytes = Bytes(c);
  EXPECT_EQ(bytes.size(), 288 + 3 * 4 + 4 * c.params.size());
  std::istringstream in(bytes);
  const Checkpoint back = ReadCheckpoint(in, "mem");
  ExpectEqual(back, c);
  ASSERT_TRUE(back.shape.sparse());
  EXPECT_EQ(back.shape.bricks->bricks, (std::vector<int64_t>{1, 4, 7}));
  EXPECT_EQ(back.shape.ParamCount(), 3 * 512 * 4 + 2 * 6 * 2 * 2 * 4);

  // A version 1 file (dense, no brick count): what version 1 wrote for the dense sample.
  std::string v1 = Bytes(Sample());
  v1.erase(264, 24);  // the brick count, the exposure count and the pose count
  const uint32_t one = 1, header = 264;
  std::memcpy(&v1[8], &one, 4);
  std::memcpy(&v1[12], &header, 4);
  std::istringstream in1(v1);
  ExpectEqual(ReadCheckpoint(in1, "v1"), Sample());
}

// A sparse header claiming a 4096^3 grid with the sample's 3 bricks: the fuzzer's 384-byte input
// of this kind made the reader build the grid's tables from n alone (670 MB for the brick slots,
// and 16 GiB for the march's skip table) before anything else. n, not in the checksum, is refused
// beyond the finest grid PERF fits.
TEST(CheckpointTest, AGridBeyondTheFinestIsRefusedBeforeItsTables) {
  for (const int32_t n : {4096, kMaxGridSize + 8}) {
    std::string huge = Bytes(SparseSample());
    std::memcpy(&huge[20], &n, 4);
    EXPECT_EQ(FieldOfError(huge), "n") << n;
  }
}

TEST(CheckpointTest, DamagedBrickListsAreNamed) {
  const std::string good = Bytes(SparseSample());
  std::string order = good;
  const uint32_t four = 4;
  std::memcpy(&order[288 + 8], &four, 4);  // bricks 1, 4, 4
  EXPECT_EQ(FieldOfError(order), "bricks");
  std::string beyond = good;
  const uint32_t eight = 8;
  std::memcpy(&beyond[288 + 8], &eight, 4);  // brick 8 of 8
  EXPECT_EQ(FieldOfError(beyond), "bricks");
  std::string count = good;
  const int64_t nine = 9;
  std::memcpy(&count[264], &nine, 8);  // more bricks than the grid has
  EXPECT_EQ(FieldOfError(count), "bricks");
  std::string flipped = good;
  flipped[288] ^= 0x02;  // brick 1 becomes 3: still ascending, but not what the checksum covers
  EXPECT_EQ(FieldOfError(flipped), "checksum");
  std::string odd = good;
  odd[20] = 12;  // n = 12: not a multiple of 8
  EXPECT_EQ(FieldOfError(odd), "n");
}

// A stream that cannot seek (like a pipe): the reader cannot ask how many bytes are left.
class PipeBuf : public std::streambuf {
 public:
  explicit PipeBuf(std::string bytes) : bytes_(std::move(bytes)) { setg(bytes_.data(), bytes_.data(), bytes_.data() + bytes_.size()); }

 private:
  std::string bytes_;
};

// The field of the InputError that reading `in` throws, checking that it names the file and
// that it came quickly (nothing the size of the claimed parameters was allocated or zeroed).
std::string FieldOfQuickError(std::istream& in) {
  const auto start = std::chrono::steady_clock::now();
  try {
    ReadCheckpoint(in, "huge.perfvol");
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("huge.perfvol"), std::string::npos) << e.what();
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
    return StrCat(e.field(), ": ", e.what());
  }
  return "read";
}

TEST(CheckpointTest, HugeCountWithShortBodyIsRefusedBeforeAllocating) {
  // 1024^3 cells and 2 x 6 x 16384^2 texels: 69 GB of parameters claimed, none there. The
  // old reader resized the vector to the claimed count first (bad_alloc, or gigabytes zeroed).
  const std::string header = HugeHeader(kMaxGridSize, 16384);
  std::istringstream in(header);
  const std::string error = FieldOfQuickError(in);
  EXPECT_EQ(error.rfind("parameters: ", 0), 0u) << error;
  EXPECT_NE(error.find(std::to_string(ParamCount(kMaxGridSize, 16384, 2))), std::string::npos) << error;  // the claimed count
  EXPECT_NE(error.find("truncated"), std::string::npos) << error;
  // A stream that cannot tell its size: read in bounded chunks, refused at the first short one.
  PipeBuf pipe(header + std::string(1000, '\0'));
  std::istream piped(&pipe);
  EXPECT_EQ(FieldOfQuickError(piped).rfind("parameters: ", 0), 0u);
  // The same through the path overload, on a file of the header alone.
  test::TempDir dir;
  std::ofstream(dir / "huge.perfvol", std::ios::binary) << HugeHeader(kMaxGridSize, 16384);
  try {
    ReadCheckpoint(dir / "huge.perfvol");
    ADD_FAILURE() << "read";
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "parameters");
    EXPECT_EQ(e.value(), std::to_string(ParamCount(kMaxGridSize, 16384, 2)));
  }
}

TEST(CheckpointTest, ShortAndLongBodiesAreNamedOnEveryStream) {
  const std::string good = Bytes(Sample());
  PipeBuf whole(good), shorter(good.substr(0, good.size() - 4)), longer(good + "x");
  std::istream a(&whole), b(&shorter), c(&longer);
  ExpectEqual(ReadCheckpoint(a, "pipe"), Sample());
  EXPECT_EQ(FieldOfQuickError(b).rfind("parameters: ", 0), 0u);
  EXPECT_EQ(FieldOfQuickError(c).rfind("size: ", 0), 0u);
}

// Inputs the fuzzer (fuzz/checkpoint_fuzzer.cc) once found a problem with: each reads or is
// refused with an InputError.
TEST(CheckpointTest, FuzzRegressionsReadOrAreRefused) {
  const std::filesystem::path dir = std::filesystem::path(PERF_SOURCE_DIR) / "fuzz/regressions/checkpoint";
  if (!std::filesystem::is_directory(dir)) GTEST_SKIP() << dir << " not found";
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(e.path(), std::ios::binary);
    try {
      ReadCheckpoint(in, e.path().string());
    } catch (const InputError&) {
    }
  }
}

TEST(CheckpointTest, MissingFileIsAnIoError) {
  test::TempDir dir;
  EXPECT_THROW(ReadCheckpoint(dir / "none.perfvol"), IoError);
}

// A crafted header whose placement no export could use is refused by field, not by OpenVDB later.
TEST(CheckpointTest, PlacementsOutOfRangeAreNamed) {
  for (const double size : {1e300, 1e-300, 0.0}) {
    Checkpoint c = Sample();
    c.placement.box_size[1] = size;
    EXPECT_EQ(FieldOfError(Bytes(c)), "box.size") << size;
  }
  Checkpoint zero = Sample();
  for (double& v : zero.placement.box_rotation) v = 0;
  EXPECT_EQ(FieldOfError(Bytes(zero)), "box.rotation");
  Checkpoint mirrored = Sample();
  for (int k = 0; k < 3; ++k) mirrored.placement.box_rotation[3 * k] *= -1;  // det -1
  EXPECT_EQ(FieldOfError(Bytes(mirrored)), "box.rotation");
  Checkpoint far = Sample();
  far.placement.shell_radii.back() = 1e300;
  EXPECT_EQ(FieldOfError(Bytes(far)), "shells.radii");
  Checkpoint away = Sample();
  away.placement.box_center[2] = 1e300;
  EXPECT_EQ(FieldOfError(Bytes(away)), "box.center");
}

// Parameters that are NaN or infinite (with a valid checksum) are refused, naming the file and
// how many: a renderer would otherwise score them as a perfect or a meaningless PSNR.
TEST(CheckpointTest, NonFiniteParametersAreRefusedWithTheirCount) {
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    Checkpoint c = Sample();
    c.params[3] = bad;
    c.params[c.params.size() - 1] = -bad;
    std::istringstream in(Bytes(c));
    try {
      ReadCheckpoint(in, "level_7.perfvol");
      ADD_FAILURE() << "read a checkpoint with " << bad;
    } catch (const InputError& e) {
      EXPECT_EQ(e.field(), "parameters");
      const std::string msg = e.what();
      EXPECT_NE(msg.find("level_7.perfvol"), std::string::npos) << msg;
      EXPECT_NE(msg.find(StrCat("2 of ", c.params.size())), std::string::npos) << msg;
    }
  }
}

// A FIFO in the checkpoint's place is refused at once instead of blocking the reader.
TEST(CheckpointTest, AFifoIsRefused) {
  test::TempDir dir;
  const auto fifo = dir / "level_0.perfvol";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  EXPECT_THROW(ReadCheckpoint(fifo), InputError);
}

}  // namespace
}  // namespace perf::recon
