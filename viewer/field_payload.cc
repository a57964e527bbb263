#include "viewer/field_payload.h"

#include <zlib.h>

#include <Eigen/Core>
#include <cstring>

#include "common/errors.h"
#include "recon_cuda/data/brick_grid.h"
#include "recon_cuda/solve/backend.h"

namespace perf::viewer {
namespace {

// Little-endian appends (x86-64 and every GPU host PERF targets are little-endian).
template <class T>
void Put(std::string* out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out->append(b, sizeof(T));
}

// values [count] as IEEE half floats (Eigen::half: round to nearest even).
void PutHalves(std::string* out, const float* values, int64_t count) {
  const size_t at = out->size();
  out->resize(at + 2 * static_cast<size_t>(count));
  for (int64_t i = 0; i < count; ++i) {
    const uint16_t h = Eigen::numext::bit_cast<uint16_t>(Eigen::half(values[i]));
    std::memcpy(out->data() + at + 2 * i, &h, 2);
  }
}

// The brick atlas the page packs the stored bricks into: as close to a cube as the count allows.
void AtlasFor(int64_t bricks, int atlas[3]) {
  int side = 1;
  while (static_cast<int64_t>(side) * side * side < bricks) ++side;
  atlas[0] = atlas[1] = side;
  atlas[2] = static_cast<int>((bricks + static_cast<int64_t>(side) * side - 1) / (static_cast<int64_t>(side) * side));
  if (atlas[2] < 1) atlas[2] = 1;
}

}  // namespace

std::string FieldPayload(const recon::Checkpoint& c, int iteration) {
  const recon::VolumeShape& s = c.shape;
  const recon::VolumeGeometry g = recon::GeometryOf(c);
  if (s.num_shells > recon::kMaxShells) {
    throw InputError("checkpoint", "num_shells", std::to_string(s.num_shells), "more shells than perf view draws",
                     StrCat("at most ", recon::kMaxShells));
  }
  const int64_t cells = s.StoredCells(), slots = s.sparse() ? recon::BrickCount(s.n) : 0;
  const int stride = s.sh_degree > 0 ? recon::ShStride(s.sh_degree) : 0;
  const uint64_t slot_bytes = 4 * static_cast<uint64_t>(slots), grid_bytes = 2 * 4 * static_cast<uint64_t>(cells);
  const uint64_t band_bytes = 2 * static_cast<uint64_t>(stride) * cells;
  const uint64_t shell_bytes = 2 * static_cast<uint64_t>(s.ShellParams());
  int atlas[3] = {0, 0, 0};
  if (s.sparse()) AtlasFor(s.bricks->ActiveBricks(), atlas);

  std::string out;
  out.reserve(kFieldHeaderBytes + slot_bytes + grid_bytes + band_bytes + shell_bytes);
  out.append("PERFFLD", 8);  // with its terminating zero
  Put<uint32_t>(&out, kFieldVersion);
  Put<uint32_t>(&out, kFieldHeaderBytes);
  for (int v : {c.level, iteration, s.n, s.m, s.num_shells, s.sh_degree,
                s.sparse() ? static_cast<int>(s.bricks->ActiveBricks()) : -1, atlas[0], atlas[1], atlas[2]}) {
    Put<int32_t>(&out, v);
  }
  for (float v : {g.box.center.x, g.box.center.y, g.box.center.z}) Put<float>(&out, v);
  for (float v : g.box.world_from_box.m) Put<float>(&out, v);
  for (float v : {g.box.size.x, g.box.size.y, g.box.size.z, g.shell_center.x, g.shell_center.y, g.shell_center.z}) {
    Put<float>(&out, v);
  }
  for (int k = 0; k < recon::kMaxShells; ++k) Put<float>(&out, k < g.num_shells() ? g.shell_radii[k] : 0.f);
  for (uint64_t b : {slot_bytes, grid_bytes, band_bytes, shell_bytes}) Put<uint64_t>(&out, b);
  Put<float>(&out, recon::ResidualSettings{}.stop_transmittance);  // where perf render's rays end
  PERF_CHECK(out.size() <= kFieldHeaderBytes);
  out.resize(kFieldHeaderBytes, '\0');

  if (s.sparse()) {
    for (int32_t slot : s.bricks->slot) Put<int32_t>(&out, slot);
  }
  const float* x = c.params.data();
  PutHalves(&out, x, 4 * cells);
  if (stride > 0) PutHalves(&out, x + s.ShStart(), stride * cells);
  PutHalves(&out, x + s.GridParamCount(), s.ShellParams());
  PERF_CHECK(out.size() == kFieldHeaderBytes + slot_bytes + grid_bytes + band_bytes + shell_bytes);
  return out;
}

std::string Gzip(const std::string& bytes) {
  PERF_CHECK_MSG(bytes.size() < (uint64_t{1} << 32), bytes.size(), " bytes to compress");
  z_stream z{};
  // 15 + 16: a gzip header and trailer (Content-Encoding: gzip); level 1: fast, most of the gain.
  PERF_CHECK(deflateInit2(&z, 1, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) == Z_OK);
  std::string out(deflateBound(&z, bytes.size()), '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
  z.avail_in = static_cast<uInt>(bytes.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  const int r = deflate(&z, Z_FINISH);
  deflateEnd(&z);
  PERF_CHECK_MSG(r == Z_STREAM_END, "deflate: ", r);
  out.resize(z.total_out);
  return out;
}

}  // namespace perf::viewer
