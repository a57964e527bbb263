// The fitted volume as perf view sends it (viewer/field_payload.h, docs/viewer_field.md): the
// header's placement, counts and section sizes; the grid, bands and shells as half floats in the
// checkpoint's order (a dense and a sparse level, with and without bands); gzip that zlib reads
// back; and FieldSource (viewer/field_source.h): the levels listed, a payload made again when its
// checkpoint changes, the live volume first when there is one. The page's own reading of it:
// view_page_test (against perf render) and field_parse_test.js.
#include <gtest/gtest.h>
#include <zlib.h>

#include <Eigen/Core>
#include <cstring>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>

#include "recon_cuda/data/brick_grid.h"
#include "recon_cuda/data/checkpoint.h"
#include "tests/test_util.h"
#include "viewer/field_payload.h"
#include "viewer/field_source.h"

namespace perf::viewer {
namespace {

namespace fs = std::filesystem;
using recon::Checkpoint;

Checkpoint Volume(int n, int degree, std::shared_ptr<const recon::BrickGrid> bricks, uint32_t seed) {
  Checkpoint c;
  c.level = 2;
  c.iterations = 5;
  c.shape = recon::VolumeShape(n, 4, 3, std::move(bricks), 0, degree);
  c.placement.box_center[0] = 1.5;
  c.placement.box_size[2] = 3;
  c.placement.box_rotation[0] = c.placement.box_rotation[4] = 0;  // a quarter turn about z
  c.placement.box_rotation[1] = -1;
  c.placement.box_rotation[3] = 1;
  c.placement.shell_radii = {2, 4, 8};
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-2.f, 40.f);
  c.params.resize(c.shape.ParamCount());
  for (float& v : c.params) v = u(rng);
  return c;
}

template <class T>
T At(const std::string& b, size_t offset) {
  T v;
  std::memcpy(&v, b.data() + offset, sizeof(T));
  return v;
}
float Half(const std::string& b, size_t offset) {
  return static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(At<uint16_t>(b, offset)));
}

void ExpectTheCheckpoint(const Checkpoint& c, const std::string& b) {
  ASSERT_GE(b.size(), kFieldHeaderBytes);
  EXPECT_EQ(std::string(b.data(), 8), std::string("PERFFLD\0", 8));
  EXPECT_EQ(At<uint32_t>(b, 8), kFieldVersion);
  EXPECT_EQ(At<uint32_t>(b, 12), kFieldHeaderBytes);
  const recon::VolumeShape& s = c.shape;
  EXPECT_EQ(At<int32_t>(b, 16), c.level);
  EXPECT_EQ(At<int32_t>(b, 20), 7);  // the iteration given
  EXPECT_EQ(At<int32_t>(b, 24), s.n);
  EXPECT_EQ(At<int32_t>(b, 28), s.m);
  EXPECT_EQ(At<int32_t>(b, 32), s.num_shells);
  EXPECT_EQ(At<int32_t>(b, 36), s.sh_degree);
  EXPECT_EQ(At<int32_t>(b, 40), s.sparse() ? s.bricks->ActiveBricks() : -1);
  const int atlas = At<int32_t>(b, 44) * At<int32_t>(b, 48) * At<int32_t>(b, 52);
  if (s.sparse()) {
    EXPECT_GE(atlas, s.bricks->ActiveBricks());
  }
  const recon::VolumeGeometry g = recon::GeometryOf(c);
  EXPECT_EQ(At<float>(b, 56), g.box.center.x);
  EXPECT_EQ(At<float>(b, 56 + 4 * 4), g.box.world_from_box.m[1]);
  EXPECT_EQ(At<float>(b, 56 + 4 * 14), g.box.size.z);
  EXPECT_EQ(At<float>(b, 56 + 4 * 15), g.shell_center.x);
  EXPECT_EQ(At<float>(b, 56 + 4 * 19), g.shell_radii[1]);
  EXPECT_EQ(At<float>(b, 56 + 4 * 21), 0.f) << "unused radii are 0";
  const uint64_t slots = At<uint64_t>(b, 160), grid = At<uint64_t>(b, 168), bands = At<uint64_t>(b, 176),
                 shells = At<uint64_t>(b, 184);
  EXPECT_EQ(At<float>(b, 192), 1e-3f) << "perf render's early termination";
  EXPECT_EQ(slots, s.sparse() ? 4 * static_cast<uint64_t>(recon::BrickCount(s.n)) : 0u);
  EXPECT_EQ(grid, 2 * static_cast<uint64_t>(s.GridParamCount()));
  EXPECT_EQ(bands, 2 * static_cast<uint64_t>(s.ShParams(s.GridParamCount())));
  EXPECT_EQ(shells, 2 * static_cast<uint64_t>(s.ShellParams()));
  ASSERT_EQ(b.size(), kFieldHeaderBytes + slots + grid + bands + shells);
  if (s.sparse()) {
    for (size_t i = 0; i < s.bricks->slot.size(); ++i) EXPECT_EQ(At<int32_t>(b, kFieldHeaderBytes + 4 * i), s.bricks->slot[i]);
  }
  // Every value within half precision of the checkpoint's, in its order.
  const size_t grid_at = kFieldHeaderBytes + slots, bands_at = grid_at + grid, shells_at = bands_at + bands;
  const auto expect_halves = [&](size_t at, int64_t first, int64_t count, const char* what) {
    for (int64_t i = 0; i < count; ++i) {
      const float want = c.params[first + i];
      ASSERT_NEAR(Half(b, at + 2 * i), want, std::abs(want) * 1e-3f + 1e-4f) << what << " value " << i;
    }
  };
  expect_halves(grid_at, 0, s.GridParamCount(), "grid");
  expect_halves(bands_at, s.ShStart(), s.ShParams(s.GridParamCount()), "bands");
  expect_halves(shells_at, s.GridParamCount(), s.ShellParams(), "shells");
}

TEST(FieldPayload, HoldsTheCheckpointsVolumeInHalfPrecision) {
  SCOPED_TRACE("dense, no bands");
  ExpectTheCheckpoint(Volume(8, 0, nullptr, 1), FieldPayload(Volume(8, 0, nullptr, 1), 7));
  std::vector<uint8_t> active(8, 0);
  active[1] = active[6] = active[7] = 1;
  auto bricks = std::make_shared<const recon::BrickGrid>(recon::MakeBrickGrid(16, active));
  SCOPED_TRACE("sparse, degree 1");
  const Checkpoint sparse = Volume(16, 1, bricks, 2);
  ExpectTheCheckpoint(sparse, FieldPayload(sparse, 7));
}

TEST(FieldPayload, GzipIsReadBackByZlib) {
  const std::string raw = FieldPayload(Volume(8, 1, nullptr, 3));
  const std::string gz = Gzip(raw);
  EXPECT_LT(gz.size(), raw.size());
  EXPECT_EQ(static_cast<unsigned char>(gz[0]), 0x1f);  // gzip's magic
  EXPECT_EQ(static_cast<unsigned char>(gz[1]), 0x8b);
  std::string back(raw.size(), '\0');
  z_stream z{};
  ASSERT_EQ(inflateInit2(&z, 15 + 16), Z_OK);
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(gz.data()));
  z.avail_in = static_cast<uInt>(gz.size());
  z.next_out = reinterpret_cast<Bytef*>(back.data());
  z.avail_out = static_cast<uInt>(back.size());
  EXPECT_EQ(inflate(&z, Z_FINISH), Z_STREAM_END);
  inflateEnd(&z);
  EXPECT_EQ(back, raw);
}

TEST(FieldSource, ListsTheLevelsAndServesTheNewestVolume) {
  test::TempDir dir;
  fs::create_directories(dir / "recon");
  FieldSource source(dir.path());
  EXPECT_EQ(source.Listing()["newest"], nullptr);
  EXPECT_FALSE(source.Payload(-1, false));
  Checkpoint a = Volume(8, 0, nullptr, 4);
  a.level = 0;
  recon::WriteCheckpoint(recon::CheckpointPath(dir.path(), 0), a);
  Checkpoint b = Volume(8, 1, nullptr, 5);
  b.level = 1;
  recon::WriteCheckpoint(recon::CheckpointPath(dir.path(), 1), b);
  const nlohmann::json list = source.Listing();
  ASSERT_EQ(list["levels"].size(), 2u);
  EXPECT_EQ(list["newest"], 1);
  EXPECT_EQ(list["live"], nullptr);
  const auto newest = source.Payload(-1, false);
  ASSERT_TRUE(newest);
  EXPECT_EQ(At<int32_t>(*newest->bytes, 16), 1);
  const auto first = source.Payload(0, true);
  ASSERT_TRUE(first && first->gzip);
  EXPECT_EQ(source.Payload(0, true)->bytes, first->bytes) << "kept for the next request";
  EXPECT_FALSE(source.Payload(5, false));
  // The checkpoint written again (a resumed run): the next request gets the new volume.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  Checkpoint a2 = Volume(16, 0, nullptr, 6);
  a2.level = 0;
  recon::WriteCheckpoint(recon::CheckpointPath(dir.path(), 0), a2);
  EXPECT_EQ(At<int32_t>(*source.Payload(0, false)->bytes, 24), 16);
  // A running solve's volume comes first when the newest is asked for.
  auto live = std::make_shared<LiveField>();
  live->volume = Volume(8, 0, nullptr, 7);
  live->volume.level = 2;
  live->iteration = 3;
  live->version = 9;
  source.SetLive([&] { return std::shared_ptr<const LiveField>(live); });
  EXPECT_EQ(source.Listing()["newest"], "live");
  EXPECT_EQ(source.Listing()["live"]["version"], 9);
  const auto l = source.Payload(-1, false);
  EXPECT_EQ(At<int32_t>(*l->bytes, 16), 2);
  EXPECT_EQ(At<int32_t>(*l->bytes, 20), 3);
  EXPECT_EQ(At<int32_t>(*source.Payload(1, false)->bytes, 16), 1) << "a level asked for is that level's";
}

}  // namespace
}  // namespace perf::viewer
