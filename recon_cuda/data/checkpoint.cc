#include "recon_cuda/data/checkpoint.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <optional>
#include <regex>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/world_range.h"

namespace perf::recon {
namespace {

static_assert(std::endian::native == std::endian::little, "checkpoints are written little-endian");

constexpr char kMagic[8] = {'P', 'E', 'R', 'F', 'V', 'O', 'L', '\0'};
constexpr uint32_t kHeaderBytesV1 = 8 + 4 + 4 + 6 * 4 + (3 + 9 + 3 + 3 + kMaxShells) * 8 + 8 + 8;
static_assert(kHeaderBytesV1 == 264);
constexpr uint32_t kHeaderBytesV2 = kHeaderBytesV1 + 8;  // + the brick count
constexpr uint32_t kHeaderBytesV3 = kHeaderBytesV2 + 8;  // + the exposure count and SH degree
constexpr uint32_t kHeaderBytes = kHeaderBytesV3 + 8;    // + the refined poses' count and 4 zero bytes (version 4)
constexpr int64_t kMaxExposures = 1 << 20;

// Whether the row-major 3x3 `r` is a rotation: R^T R = I and det R = 1, within float rounding.
bool IsRotation(const double (&r)[9]) {
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      double dot = 0;
      for (int k = 0; k < 3; ++k) dot += r[3 * k + a] * r[3 * k + b];
      if (std::abs(dot - (a == b ? 1.0 : 0.0)) > 1e-5) return false;
    }
  }
  const double det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6]) +
                     r[2] * (r[3] * r[7] - r[4] * r[6]);
  return det > 0;
}

constexpr uint64_t kFnvBasis = 0xcbf29ce484222325ull;
uint64_t Fnv1a(const void* data, size_t n, uint64_t h = kFnvBasis) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

template <class T>
void Put(std::string* buf, const T& v) {
  buf->append(reinterpret_cast<const char*>(&v), sizeof(T));
}

class Reader {
 public:
  Reader(std::istream& in, const std::string& name) : in_(in), name_(name) {}
  template <class T>
  T Get(const char* field) {
    T v;
    if (!in_.read(reinterpret_cast<char*>(&v), sizeof(T))) Truncated(field);
    return v;
  }
  [[noreturn]] void Truncated(const char* field, const std::string& value = "",
                              const std::string& problem = "the checkpoint is truncated") {
    throw InputError(name_, field, value, problem,
                     "it was not written completely, or is not a PERF checkpoint: a workspace's is rewritten by "
                     "running perf reconstruct again (--resume restarts from the previous level); otherwise pass a "
                     "checkpoint perf reconstruct wrote (WORKSPACE/recon/level_<k>.perfvol)");
  }
  [[noreturn]] void Bad(const char* field, const std::string& value, const std::string& problem) {
    throw InputError(name_, field, value, problem,
                     "the checkpoint is damaged or not a PERF checkpoint: a workspace's is rewritten by running perf "
                     "reconstruct again; otherwise pass a checkpoint perf reconstruct wrote "
                     "(WORKSPACE/recon/level_<k>.perfvol)");
  }
  std::istream& in() { return in_; }

 private:
  std::istream& in_;
  const std::string& name_;
};

// Bytes left in `in` after its read position, or nullopt where the stream cannot seek (a pipe).
std::optional<uint64_t> BytesLeft(std::istream& in) {
  const std::streampos here = in.tellg();
  if (here == std::streampos(-1)) return std::nullopt;
  in.seekg(0, std::ios::end);
  const std::streampos end = in.tellg();
  in.clear();
  in.seekg(here);
  if (end == std::streampos(-1) || !in || end < here) {
    in.clear();
    return std::nullopt;
  }
  return static_cast<uint64_t>(end - here);
}

[[noreturn]] void ParamsTruncated(Reader& r, uint64_t count, const std::string& found) {
  r.Truncated("parameters", StrCat(count), StrCat("the checkpoint is truncated: its parameter count ", count, " needs ",
                                                  count * sizeof(float), " bytes after the header", found));
}

// Checks the header's counts (parameters, and `bricks` u32 before them) against the bytes that
// follow it, before anything is allocated for them. False where the stream cannot tell (ReadArray
// then bounds the memory).
bool CheckParamBytes(Reader& r, uint64_t count, uint64_t bricks) {
  const std::optional<uint64_t> left = BytesLeft(r.in());
  if (!left) return false;
  const uint64_t needed = count * sizeof(float) + bricks * sizeof(uint32_t);
  if (*left < needed) ParamsTruncated(r, count, StrCat(", the file has ", *left));
  if (*left > needed) r.Bad("size", StrCat(*left - needed, " bytes"), "trailing bytes after the parameters");
  return true;
}

// `count` values of T. Unless `checked` (CheckParamBytes found them all there), read in chunks,
// so that a stream that ends early costs no more memory than it held.
template <class T>
std::vector<T> ReadArray(Reader& r, uint64_t count, bool checked) {
  constexpr uint64_t kChunk = uint64_t{1} << 22;  // values (16 MiB of floats)
  std::vector<T> out;
  if (checked) out.reserve(count);
  for (uint64_t done = 0; done < count;) {
    const uint64_t n = std::min(kChunk, count - done);
    out.resize(done + n);
    if (!r.in().read(reinterpret_cast<char*>(out.data() + done), static_cast<std::streamsize>(n * sizeof(T)))) {
      ParamsTruncated(r, count, "");
    }
    done += n;
  }
  return out;
}

// The brick grid of a version 2 checkpoint's list (ascending indices below nb^3).
std::shared_ptr<const BrickGrid> BricksFromList(Reader& r, int n, const std::vector<uint32_t>& list) {
  const int64_t total = BrickCount(n);
  std::vector<uint8_t> active(static_cast<size_t>(total), 0);
  for (size_t i = 0; i < list.size(); ++i) {
    if (list[i] >= total || (i > 0 && list[i] <= list[i - 1])) {
      r.Bad("bricks", StrCat(list[i]), StrCat("brick indices must ascend and be below ", total));
    }
    active[list[i]] = 1;
  }
  return std::make_shared<const BrickGrid>(MakeBrickGrid(n, active));
}

}  // namespace

void WriteCheckpoint(std::ostream& out, const Checkpoint& c) {
  PERF_CHECK(static_cast<int64_t>(c.params.size()) == c.shape.ParamCount());
  PERF_CHECK(static_cast<int>(c.placement.shell_radii.size()) == c.shape.num_shells && c.shape.num_shells <= kMaxShells);
  std::string h;
  h.append(kMagic, 8);
  Put(&h, kCheckpointVersion);
  Put(&h, kHeaderBytes);
  for (int32_t v : {c.level, c.shape.n, c.shape.m, c.shape.num_shells, c.iterations, c.solver}) Put(&h, v);
  const VolumePlacement& p = c.placement;
  for (double v : p.box_center) Put(&h, v);
  for (double v : p.box_rotation) Put(&h, v);
  for (double v : p.box_size) Put(&h, v);
  for (double v : p.shell_center) Put(&h, v);
  for (int k = 0; k < kMaxShells; ++k) Put(&h, k < c.shape.num_shells ? p.shell_radii[k] : 0.0);
  std::vector<uint32_t> bricks;
  if (c.shape.bricks) bricks.assign(c.shape.bricks->bricks.begin(), c.shape.bricks->bricks.end());
  Put(&h, static_cast<uint64_t>(c.params.size()));
  Put(&h, Fnv1a(c.params.data(), c.params.size() * sizeof(float), Fnv1a(bricks.data(), bricks.size() * sizeof(uint32_t))));
  Put(&h, static_cast<int64_t>(c.shape.bricks ? static_cast<int64_t>(bricks.size()) : -1));
  Put(&h, static_cast<int32_t>(c.shape.exposures));
  Put(&h, static_cast<int32_t>(c.shape.sh_degree));
  Put(&h, static_cast<int32_t>(c.shape.poses));
  Put(&h, int32_t{0});
  PERF_CHECK(h.size() == kHeaderBytes);
  out.write(h.data(), static_cast<std::streamsize>(h.size()));
  out.write(reinterpret_cast<const char*>(bricks.data()), static_cast<std::streamsize>(bricks.size() * sizeof(uint32_t)));
  out.write(reinterpret_cast<const char*>(c.params.data()), static_cast<std::streamsize>(c.params.size() * sizeof(float)));
}

Checkpoint ReadCheckpoint(std::istream& in, const std::string& name) {
  Reader r(in, name);
  char magic[8];
  if (!in.read(magic, 8)) r.Truncated("magic");
  if (std::memcmp(magic, kMagic, 8) != 0) r.Bad("magic", std::string(magic, strnlen(magic, 8)), "not a PERF volume checkpoint");
  const uint32_t version = r.Get<uint32_t>("version");
  if (version < 1 || version > kCheckpointVersion) {
    throw InputError(name, "version", std::to_string(version),
                     StrCat("this perf reads checkpoint versions 1 to ", kCheckpointVersion),
                     "re-run perf reconstruct with this version of perf");
  }
  const uint32_t header = r.Get<uint32_t>("header bytes");
  const uint32_t expected_header = version == 1   ? kHeaderBytesV1
                                   : version == 2 ? kHeaderBytesV2
                                   : version == 3 ? kHeaderBytesV3
                                                  : kHeaderBytes;
  if (header != expected_header) r.Bad("header bytes", std::to_string(header), StrCat("expected ", expected_header));
  Checkpoint c;
  c.level = r.Get<int32_t>("level");
  c.shape.n = r.Get<int32_t>("n");
  c.shape.m = r.Get<int32_t>("m");
  c.shape.num_shells = r.Get<int32_t>("num_shells");
  c.iterations = r.Get<int32_t>("iterations");
  c.solver = r.Get<int32_t>("solver");
  if (c.level < 0 || c.level > 16) r.Bad("level", std::to_string(c.level), "out of range");
  if (c.shape.n < 1 || c.shape.n > kMaxGridSize) {
    r.Bad("n", std::to_string(c.shape.n), StrCat("grid size out of range (1 to ", kMaxGridSize, ")"));
  }
  if (c.shape.m < 1 || c.shape.m > 16384) r.Bad("m", std::to_string(c.shape.m), "face size out of range");
  if (c.shape.num_shells < 1 || c.shape.num_shells > kMaxShells) {
    r.Bad("num_shells", std::to_string(c.shape.num_shells), StrCat("must be 1 to ", kMaxShells));
  }
  if (c.solver != 0 && c.solver != 1) r.Bad("solver", std::to_string(c.solver), "must be 0 or 1");
  auto get_finite = [&](const char* field) {
    const double v = r.Get<double>(field);
    if (!std::isfinite(v)) r.Bad(field, StrCat(v), "not finite");
    return v;
  };
  // A centre (or a shell centre) beyond the world span is as unplaceable as a box that large.
  auto get_position = [&](const char* field) {
    const double v = get_finite(field);
    if (!(std::abs(v) <= kMaxWorldSpan)) r.Bad(field, StrCat(v), StrCat("must be within ", kMaxWorldSpan, " world units of the origin"));
    return v;
  };
  VolumePlacement& p = c.placement;
  for (double& v : p.box_center) v = get_position("box.center");
  for (double& v : p.box_rotation) v = get_finite("box.rotation");
  if (!IsRotation(p.box_rotation)) r.Bad("box.rotation", "", "not a rotation (orthonormal, determinant 1)");
  for (double& v : p.box_size) {
    v = get_finite("box.size");
    if (!(v >= kMinBoxSide && v <= kMaxWorldSpan)) {
      r.Bad("box.size", StrCat(v), StrCat("must be ", kMinBoxSide, " to ", kMaxWorldSpan, " world units"));
    }
  }
  for (double& v : p.shell_center) v = get_position("shells.center");
  for (int k = 0; k < kMaxShells; ++k) {
    const double radius = get_finite("shells.radii");
    if (k < c.shape.num_shells && !(radius <= kMaxWorldSpan)) {
      r.Bad("shells.radii", StrCat(radius), StrCat("must be at most ", kMaxWorldSpan, " world units"));
    }
    if (k < c.shape.num_shells) {
      if (!(radius > 0) || (k > 0 && !(radius > p.shell_radii.back()))) {
        r.Bad("shells.radii", StrCat(radius), "radii must be positive and increasing");
      }
      p.shell_radii.push_back(radius);
    }
  }
  const uint64_t count = r.Get<uint64_t>("parameter count");
  const uint64_t checksum = r.Get<uint64_t>("checksum");
  const int64_t num_bricks = version == 1 ? -1 : r.Get<int64_t>("bricks");
  if (num_bricks >= 0) {
    if (c.shape.n % kBrickSide != 0) {
      r.Bad("n", std::to_string(c.shape.n), StrCat("a sparse grid's size must be a multiple of ", kBrickSide));
    }
    const int64_t total = BrickCount(c.shape.n);
    if (num_bricks > total) r.Bad("bricks", StrCat(num_bricks), StrCat("more than the grid's ", total));
  } else if (num_bricks != -1) {
    r.Bad("bricks", StrCat(num_bricks), "must be -1 (dense) or a brick count");
  }
  const int32_t exposures = version < 3 ? 0 : r.Get<int32_t>("exposures");
  if (exposures < 0 || exposures > kMaxExposures) {
    r.Bad("exposures", StrCat(exposures), StrCat("must be 0 to ", kMaxExposures, " photos"));
  }
  c.shape.exposures = exposures;
  const int32_t sh_degree = version < 3 ? 0 : r.Get<int32_t>("sh_degree");
  if (sh_degree < 0 || sh_degree > 2) r.Bad("sh_degree", StrCat(sh_degree), "must be 0, 1 or 2");
  c.shape.sh_degree = sh_degree;
  const int32_t poses = version < 4 ? 0 : r.Get<int32_t>("poses");
  if (poses < 0 || poses > kMaxExposures) r.Bad("poses", StrCat(poses), StrCat("must be 0 to ", kMaxExposures, " photos"));
  c.shape.poses = poses;
  if (version >= 4 && r.Get<int32_t>("reserved") != 0) r.Bad("reserved", "", "must be 0");
  // The parameter count the shape implies, before the brick list is read (it needs only B).
  const int64_t grid_params = num_bricks >= 0 ? SparseGridParams(num_bricks) : GridParamCount(c.shape.n);
  const int64_t expected = c.shape.ParamCountFor(grid_params);
  if (count != static_cast<uint64_t>(expected)) {
    r.Bad("parameter count", std::to_string(count), StrCat("expected ", expected, " for the shape"));
  }
  const uint64_t list_size = num_bricks >= 0 ? static_cast<uint64_t>(num_bricks) : 0;
  const bool checked = CheckParamBytes(r, count, list_size);
  const std::vector<uint32_t> list = ReadArray<uint32_t>(r, list_size, checked);
  if (num_bricks >= 0) c.shape.bricks = BricksFromList(r, c.shape.n, list);
  c.params = ReadArray<float>(r, count, checked);
  if (Fnv1a(c.params.data(), count * sizeof(float), Fnv1a(list.data(), list.size() * sizeof(uint32_t))) != checksum) {
    r.Bad("checksum", "", "the parameters do not match the checksum");
  }
  if (in.peek() != std::char_traits<char>::eof()) r.Bad("size", "", "trailing bytes after the parameters");
  // Values, not only the header: a NaN scores as a perfect or a meaningless PSNR and spreads
  // through a resumed solve.
  const int64_t not_finite = std::count_if(c.params.begin(), c.params.end(), [](float v) { return !std::isfinite(v); });
  if (not_finite > 0) r.Bad("parameters", StrCat(not_finite, " of ", count), "not finite (NaN or infinite)");
  return c;
}

void WriteCheckpoint(const std::filesystem::path& path, const Checkpoint& c) {
  // Durable: a later run resumes from it, so it is fsynced before and after the rename.
  WriteStreamAtomically(path, [&](std::ostream& out) { WriteCheckpoint(out, c); }, Durability::kDurable);
}

Checkpoint ReadCheckpoint(const std::filesystem::path& path) {
  if (std::error_code ec; !std::filesystem::exists(path, ec)) {
    throw IoError(path.string(), "cannot open the checkpoint", "run perf reconstruct on the workspace first");
  }
  CheckRegularFile(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), "cannot open the checkpoint", "run perf reconstruct on the workspace first");
  return ReadCheckpoint(in, path.string());
}

std::filesystem::path CheckpointPath(const std::filesystem::path& workspace, int level) {
  return workspace / "recon" / ("level_" + std::to_string(level) + ".perfvol");
}

int LastCheckpointLevel(const std::filesystem::path& workspace) {
  int last = -1;
  std::error_code ec;
  const std::regex pattern("level_([0-9]+)\\.perfvol");
  for (const auto& e : std::filesystem::directory_iterator(workspace / "recon", ec)) {
    std::smatch m;
    const std::string name = e.path().filename().string();
    if (std::regex_match(name, m, pattern)) last = std::max(last, std::stoi(m[1]));
  }
  return last;
}

}  // namespace perf::recon
