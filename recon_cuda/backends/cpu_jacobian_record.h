// The CPU backend's per-ray sinks and the Jacobian record that Linearize keeps for MultiplyJtJ
// (cpu_backend.cc): the partials of every sample and shell of every ray, block by block. Internal
// to the CPU backend.
#pragma once

#include <bit>
#include <cstdint>
#include <vector>

#include "common/errors.h"
#include "recon_cuda/core/jacobian.h"
#include "recon_cuda/core/pose.h"
#include "recon_cuda/core/ray_math.h"
#include "recon_cuda/core/training_ray.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {
class CpuVectors;
}

namespace perf::recon::cpu {

// Plain adds into a per-thread buffer. Linearize keeps J^T r and the diagonal in one buffer,
// interleaved in groups of 4 (element i of g at 2 (i - i % 4) + i % 4, of diag 4 further), so that
// a cell's flush touches one 32-byte block instead of two distant ones: shift 1, offset 0 or 4.
struct AddSink {
  float* a;
  int shift = 0, offset = 0;
  void Add4(int64_t i, float x, float y, float z, float w) {
    float* p = a + (i << shift) + offset;
    p[0] += x;
    p[1] += y;
    p[2] += z;
    p[3] += w;
  }
};

// A float rounded to bfloat16 (its top 16 bits, to nearest, ties to even), and back.
inline uint16_t ToBfloat16(float x) {
  uint32_t u = std::bit_cast<uint32_t>(x);
  u += 0x7fffu + ((u >> 16) & 1u);
  return static_cast<uint16_t>(u >> 16);
}
inline float FromBfloat16(uint16_t h) { return std::bit_cast<float>(static_cast<uint32_t>(h) << 16); }

// A ray's pose row (pose.h PoseRow) without its padding column: 4 residuals x 7 values.
inline constexpr int kPoseRowValues = 4 * kPoseSolved;

// One sample of a ray's Jacobian, as recorded by Linearize: exact, or compact (CpuBackendOptions::
// compact_jacobian): its colour partials in bfloat16 (8 bits of mantissa) and, apart (BlockJ::
// steps), one byte: how many march steps it lies before the ray's entry before (Backward records a
// ray back to front), so its march index, whose t and delta StepAt recomputes exactly (9 bytes a
// sample). Its dl is the ray's DlPerDelta times delta, as Backward makes it, so it is not stored.
// That dl is rounded to bfloat16 as the others are, so the product is the 12-byte record's to the
// bit (left exact, the two-rank MPI test's cost bound failed; docs/tuning.md "dl not recorded").
// A gap of more than kMaxStep steps between two samples of a ray is bridged by fillers: entries
// whose partials are all 0, dl too, which add exact zeros to J^T J p.
struct SampleJ {
  float t;
  SamplePartials<float> sp;
};
struct CompactSampleJ {
  static constexpr int kMaxStep = 255;
  static constexpr uint16_t kFiller = 0xffff;  // sp[0] of a filler (a bfloat16 NaN)
  uint16_t sp[4];  // dc, ds[3]
  static CompactSampleJ Make(const SamplePartials<float>& p) {
    return {{ToBfloat16(p.dc), ToBfloat16(p.ds[0]), ToBfloat16(p.ds[1]), ToBfloat16(p.ds[2])}};
  }
  static CompactSampleJ Filler() { return {{kFiller, 0, 0, 0}}; }
  SamplePartials<float> Partials(float dl) const {
    if (sp[0] == kFiller) return {0.f, {0.f, 0.f, 0.f}, 0.f};
    return {FromBfloat16(sp[0]), {FromBfloat16(sp[1]), FromBfloat16(sp[2]), FromBfloat16(sp[3])}, dl};
  }
};
static_assert(sizeof(CompactSampleJ) == 8, "8 bytes of partials a recorded sample, and its step");
struct ShellJ {
  CubeCoord<float> coord;  // face -1: the ray misses this shell
  ShellPartials<float> sp;
};

// The recorded Jacobian of one block of rays.
struct BlockJ {
  bool compact = false;                 // its samples are in `packed` and `steps`, else in `samples`
  std::vector<SampleJ> samples;
  std::vector<CompactSampleJ> packed;
  std::vector<uint8_t> steps;     // [entries of packed]: march steps back from the ray's entry before (first: 0)
  std::vector<uint16_t> first_k;  // [rays] when compact: the march index of the ray's first entry (its last sample)
  std::vector<uint32_t> end;  // [rays]: one past the ray's last sample in `samples` (`packed`)
  std::vector<ShellJ> shells;  // [rays, num_shells] when exact
  // [rays] when compact: the ray's box transmittance T_box, from which and the shells' values at
  // the linearisation point RecordedShells recomputes the shells' partials (64 bytes a ray with 4
  // shells, stored in float before; bfloat16 was too coarse: docs/tuning.md "Shells recomputed").
  std::vector<float> t_box;
  std::vector<float> h;        // [rays, 3] the composited colour H (the exposure's partials)
  std::vector<float> scale;    // [rays] the robust loss's row scale (jacobian.h RobustRowScale)
  std::vector<float> dl_per_delta;  // [rays] when compact: ray_math.h DlPerDelta
  // [rays, kPoseRowValues] each ray's pose row (StorePose), when poses are refined: in `pose`
  // when exact, in `packed_pose` (bfloat16) when compact.
  std::vector<float> pose;
  std::vector<uint16_t> packed_pose;

  // Empty, for `rays` rays of a level of `shape`, exact or compact.
  void Clear(int64_t rays, const VolumeShape& shape, bool compact_samples = false);
  // One past the last sample recorded.
  uint32_t SampleCount() const { return static_cast<uint32_t>(compact ? packed.size() : samples.size()); }
  // Ray r's pose row, stored and read back (rounded to bfloat16 when compact).
  void StorePose(int64_t r, const PoseRow<float>& row);
  PoseRow<float> PoseAt(int64_t r) const;
  // Compact: appends sample k of ray r (its partials), which lies before the ray's sample last_k
  // (-1: the ray's first entry); last_k becomes k.
  void AppendCompact(int64_t r, int k, const SamplePartials<float>& p, int* last_k);
  // Compact: writes entry e, sample k of ray r, at entry *at (and fillers before it where needed),
  // after the ray's sample last_k (-1: none); *at moves past it. In place over the ray's own
  // entries when some are dropped: it never writes past the entry it is given.
  void EncodeCompact(int64_t r, int k, CompactSampleJ e, uint32_t* at, int* last_k);
};

// A recorded ray's shells as J^T J p reads them: which the ray meets, their texel weights and
// partials (the compact record recomputes where the ray meets them, from the ray and its march).
struct RayShellsJ {
  bool hit[kMaxShells];
  TexelSample<float> ts[kMaxShells];
  ShellPartials<float> sp[kMaxShells];
};
// vol: at the linearisation point (the compact record recomputes the shells' lookups and values
// there, as Backward made them: the same partials to the bit).
inline void RecordedShells(const BlockJ& b, int64_t r, const VolumeView<float>& vol, const BoxRay<float>& ray,
                           const March<float>& m, RayShellsJ* out) {
  const int n = vol.num_shells;
  if (b.compact) {
    ShellStack<float> st;
    EvalShells(vol, ray, m, &st, out->ts);
    float behind[3] = {0.f, 0.f, 0.f};
    for (int k = n - 1; k >= 0; --k) {
      out->hit[k] = st.hit[k];
      if (!st.hit[k]) continue;
      out->sp[k] = ShellPartialsAt(st, k, n, b.t_box[r], behind);
    }
    return;
  }
  for (int k = 0; k < n; ++k) {
    const ShellJ& sj = b.shells[r * n + k];
    out->hit[k] = sj.coord.face >= 0;
    out->sp[k] = sj.sp;
    if (out->hit[k]) out->ts[k] = TexelWeights(vol.GridParams(), vol.m, k, sj.coord);
  }
}

// A recorded ray's samples in order (the r-th ray of the block's record, of march m and jitter
// jit, whose first entry is `first`): each one's position t on the ray and its partials.
class RecordedSamples {
 public:
  RecordedSamples(const BlockJ& b, const March<float>& m, const Jitter& jit, int64_t r, uint32_t first)
      : b_(b), m_(m), jit_(jit), r_(r), j_(first), k_(b.compact ? b.first_k[r] : 0) {}
  // The next sample's t; its partials into *sp.
  float Next(SamplePartials<float>* sp) {
    const uint32_t j = j_++;
    if (!b_.compact) {
      *sp = b_.samples[j].sp;
      return b_.samples[j].t;
    }
    k_ -= b_.steps[j];
    const MarchStep<float> st = StepAt(m_, k_, jit_);
    *sp = b_.packed[j].Partials(FromBfloat16(ToBfloat16(b_.dl_per_delta[r_] * st.delta)));
    return st.t;
  }
  int k() const { return k_; }  // the march index of the last sample read (compact)

 private:
  const BlockJ& b_;
  const March<float>& m_;
  const Jitter& jit_;
  int64_t r_;
  uint32_t j_;
  int k_;
};

// Keeps, in place, the samples of a block's record for which keep(ray, t, sp, k) holds (t: the
// sample's position on the ray; k: its march index, compact record only), re-encoding the compact
// record's march steps. ray_of(r): the block's r-th ray as keep takes it, with its March (`march`,
// used by the compact record) and Jitter (`jit`).
template <class RayOf, class Keep>
void KeepRecordedSamples(RayOf&& ray_of, Keep&& keep, BlockJ* block) {
  uint32_t first = 0, kept = 0;
  for (size_t r = 0; r < block->end.size(); ++r) {
    const auto ray = ray_of(r);
    RecordedSamples read(*block, ray.march, ray.jit, static_cast<int64_t>(r), first);
    int last_k = -1;
    for (uint32_t j = first; j < block->end[r]; ++j) {
      SamplePartials<float> sp;
      const float t = read.Next(&sp);
      if (!keep(ray, t, sp, read.k())) continue;
      if (block->compact) block->EncodeCompact(static_cast<int64_t>(r), read.k(), block->packed[j], &kept, &last_k);
      else block->samples[kept++] = block->samples[j];
    }
    first = block->end[r];
    block->end[r] = kept;
  }
  if (block->compact) {
    block->packed.resize(kept);
    block->steps.resize(kept);
  } else {
    block->samples.resize(kept);
  }
}

// Drops the samples of a block's record that reach no free parameter with a non-zero value
// (jacobian.h SkippableSample; free: the free-parameter mask). ray_of(r): its r-th ray (TrainingRay).
template <class RayOf>
void DropSkippableSamples(const VolumeView<float>& vol, const float* free, RayOf&& ray_of, BlockJ* block) {
  struct Ray {
    TrainingRay tr;
    March<float> march;
    Jitter jit;
  };
  KeepRecordedSamples(
      [&](size_t r) {
        const TrainingRay tr = ray_of(r);
        return Ray{tr, block->compact ? MakeMarch(vol, tr.ray) : March<float>{}, tr.jit};
      },
      [&](const Ray& ray, float t, const SamplePartials<float>& sp, int) {
        return !SkippableSample(TrilinearWeights(vol.n, vol.brick_slot, ray.tr.ray.GridPoint(t)), sp, free);
      },
      block);
}

// One recorded ray's J^T J p on its volume cells, merged, with spherical harmonics (jacobian.h
// AddJpSample, AddShColour, ScatterJtuSample, ScatterSh): a sample enters J p and J^T u through
// its five partials (dc, ds[3], dl) times its cells' trilinear weights, so what a cell sees over
// the whole ray is five numbers, K = sum_j w_jq (dc, ds[0], ds[1], ds[2], dl)_j over the samples j
// that reach it (corner q). Each cell and its bands are read once and written once per ray
// instead of once per sample (3 to 5 samples reach a cell). Filled by a CellMerger<float, 5> of the
// samples' partials (this is its flush), which also asks for the cells' lines ahead of AddJp and
// ScatterJtu. At degree 0 the merge costs more than it saves (docs/tuning.md "CPU speed").
struct RayCells {
  static constexpr int K = 5;
  struct Cell {
    int64_t cell;
    float k[K];
  };
  std::vector<Cell> cells;
  const float* p = nullptr;  // the vector AddJp reads
  float* sums = nullptr;     // the per-thread sums ScatterJtu adds to
  RaySh<float> sh{};

  void Begin(const float* p_in, float* sums_in, const RaySh<float>& sh_in) {
    cells.clear();
    p = p_in;
    sums = sums_in;
    sh = sh_in;
  }
  void operator()(int64_t cell, const float* k) {
    const int64_t at = GridParam(cell, 0);
    __builtin_prefetch(p + at);
    __builtin_prefetch(sums + at, 1);
    const int64_t b = ShParam(sh.start, sh.degree, cell, 0, 0), last = ShStride(sh.degree) - 1;
    __builtin_prefetch(p + b);
    __builtin_prefetch(p + b + last);  // a cell's bands may span two lines
    __builtin_prefetch(sums + b, 1);
    __builtin_prefetch(sums + b + last, 1);
    cells.push_back({cell, {k[0], k[1], k[2], k[3], k[4]}});
  }
  // y[0 .. stride) += a x[0 .. stride); the degree-1 stride as a constant, so that the compiler
  // makes it three vector multiply-adds.
  static void AddScaled(int stride, float a, const float* x, float* y) {
    if (stride == ShStride(1)) {
      for (int i = 0; i < ShStride(1); ++i) y[i] += a * x[i];
    } else {
      for (int i = 0; i < stride; ++i) y[i] += a * x[i];
    }
  }
  // u += the ray's J p on its cells: u[c] += dc (p_c + sum_k y_k band_kc) + ds[c] p_sigma,
  // u[3] += dl p_sigma. The bands are summed with dc over the cells first (all of a block, in
  // fours: the compiler's vector adds), then dotted with the ray's y once.
  void AddJp(float u[4]) const {
    const int stride = ShStride(sh.degree);
    float bands[kMaxShStride] = {};
    for (const Cell& c : cells) {
      const float* g = p + GridParam(c.cell, 0);
      for (int ch = 0; ch < 3; ++ch) u[ch] += c.k[0] * g[ch] + c.k[1 + ch] * g[3];
      u[3] += c.k[4] * g[3];
      AddScaled(stride, c.k[0], p + ShParam(sh.start, sh.degree, c.cell, 0, 0), bands);
    }
    for (int k = 0; k < sh.bands; ++k)
      for (int ch = 0; ch < 3; ++ch) u[ch] += sh.y[k] * bands[3 * k + ch];
  }
  // The ray's J^T uv into its cells: colour c += dc uv[c], band k of c += dc y_k uv[c] (y_k uv[c]
  // formed once a ray; the padding gets zeros), sigma += ds . uv + dl uv[3].
  void ScatterJtu(const float uv[4]) const {
    const int stride = ShStride(sh.degree);
    float yuv[kMaxShStride] = {};
    for (int k = 0; k < sh.bands; ++k)
      for (int ch = 0; ch < 3; ++ch) yuv[3 * k + ch] = sh.y[k] * uv[ch];
    for (const Cell& c : cells) {
      float* g = sums + GridParam(c.cell, 0);
      for (int ch = 0; ch < 3; ++ch) g[ch] += c.k[0] * uv[ch];
      g[3] += c.k[1] * uv[0] + c.k[2] * uv[1] + c.k[3] * uv[2] + c.k[4] * uv[3];
      AddScaled(stride, c.k[0], yuv, sums + ShParam(sh.start, sh.degree, c.cell, 0, 0));
    }
  }
};

struct Scratch {
  std::vector<SampleRecord<float>> record;  // [max samples a ray]
  std::vector<GridSample<float>> weights;   // [max samples a ray]
  std::vector<SamplePartials<float>> partials;  // [max samples a ray]: a recorded ray's, unpacked
  BlockJ row;                               // one ray, when recomputing
  std::vector<float> acc;                   // per-thread sums (Linearize: g and diag interleaved)
  std::vector<double> pose_blocks;          // per-thread sums of the pose blocks (kPoseBlock a photo)
  RayCells cells;                           // MultiplyJtJ: a ray's cells and their summed partials
  uint64_t pass = 0;                        // the pass acc was zeroed for
};

// Collects a ray's partials: the gradient (and diagonal) scatter, merged cell by cell along the
// ray (jacobian.h), and optionally the record that MultiplyJtJ reuses.
// With the diagonal, J^T r goes through the same merge as the diagonal's row entries (needed for
// exactness there, and it halves the scatters); without (Adam), a direct scatter measured faster.
template <bool kDiag>
struct LinearizeVisitor {
  static constexpr int K = 9;  // J^T r values, then the 5 row values of diag
  float r[4];          // the residuals the volume's partials multiply (jacobian.h VolumeU)
  float g2[3];         // the squared gains of the ray's photo (jacobian.h GainSquared)
  AddSink g, d;
  BlockJ* out;         // nullptr: nothing recorded
  ShellJ* out_shells;  // [num_shells] of this ray, exact record (the compact one recomputes them)
  int64_t out_ray = 0;  // the ray's index in *out
  int last_k = -1;      // the march index of the ray's last sample recorded (compact)
  RaySh<float> sh{};   // the ray's spherical harmonics (degree 0: none; SetSh)
  float yr[kMaxShStride] = {}, yg2[kMaxShStride] = {};  // SetSh's y_k r_c and y_k^2 g2_c at 3 k + c
  CellMerger<float, K> merger{};
  // GN: the Forward record that Backward walks back to front, and the next of its samples whose
  // cells' sums lines are asked for (PrefetchAhead), a few samples ahead of the merged scatter.
  const SampleRecord<float>* ahead = nullptr;
  int next_ahead = -1;
  int prefetched_lo[3] = {-1, -1, -1};

  // Starts the prefetch for a ray whose Forward recorded `count` samples in `record`.
  void BeginAhead(const SampleRecord<float>* record, int count) {
    ahead = record;
    next_ahead = count - 1;
    prefetched_lo[0] = -1;
    for (int i = 0; i < kPrefetchSamples; ++i) PrefetchAhead();
  }
  void PrefetchAhead() {
    if (!kDiag || next_ahead < 0) return;
    const SampleRecord<float>& rec = ahead[next_ahead--];
    const GridSample<float>& gs = rec.gs;
    if (gs.lo[0] == prefetched_lo[0] && gs.lo[1] == prefetched_lo[1] && gs.lo[2] == prefetched_lo[2]) return;
    // keep = 1: the sample's dc is 0 and it adds nothing to its cells' bands (AddBands);
    // its cells are not marked as asked for, so that a next sample there asks for the bands.
    const bool no_bands = rec.keep == 1.f;
    if (!no_bands)
      for (int a = 0; a < 3; ++a) prefetched_lo[a] = gs.lo[a];
    const int band_floats = no_bands ? 0 : ShStride(sh.degree) << g.shift;  // g and diag interleaved (AddSink)
    for (int q = 0; q < 8; ++q) {
      if (gs.cell[q] < 0) continue;
      __builtin_prefetch(g.a + (GridParam(gs.cell[q], 0) << g.shift), 1);
      if (band_floats == 0) continue;
      const float* b = g.a + (ShParam(sh.start, sh.degree, gs.cell[q], 0, 0) << g.shift);
      for (int o = 0; o < band_floats; o += 16) __builtin_prefetch(b + o, 1);
      __builtin_prefetch(b + band_floats - 1, 1);
    }
  }
  static constexpr int kPrefetchSamples = 3;

  void Shell(int k, const CubeCoord<float>& c, const TexelSample<float>& ts, const ShellPartials<float>& sp) {
    ScatterJtuShell(ts, sp, r, g);
    if constexpr (kDiag) AddDiagShell(ts, sp, g2, d);
    if (out_shells) out_shells[k] = {c, sp};
  }
  void Sample(int k, const MarchStep<float>& st, const GridSample<float>& gs, const SamplePartials<float>& sp) {
    if constexpr (kDiag) {
      PrefetchAhead();
      float v[K];
      JtuValues(sp, r, v);
      RowValues(sp, v + 4);
      merger.Sample(gs, v, *this);
    } else {
      ScatterJtuSample(gs, sp, r, g, sh);
    }
    if (out && out->compact) out->AppendCompact(out_ray, k, sp, &last_k);
    else if (out) out->samples.push_back({st.t, sp});
  }
  // Sets the ray's spherical harmonics, after r and g2: with the diagonal, a cell's bands get
  // dc y_k r_c in J^T r and dc^2 y_k^2 g2_c in the diagonal (what jacobian.h's ScatterSh and
  // AddDiagSh add, as its merged J^T r colour is dc r_c), so both are formed here once a ray
  // (padding 0) for AddBands.
  void SetSh(const RaySh<float>& ray_sh) {
    sh = ray_sh;
    if (!kDiag || sh.degree == 0) return;
    for (int i = 0; i < ShStride(sh.degree); ++i) yr[i] = yg2[i] = 0.f;
    for (int k = 0; k < sh.bands; ++k)
      for (int c = 0; c < 3; ++c) {
        yr[3 * k + c] = sh.y[k] * r[c];
        yg2[3 * k + c] = sh.y[k] * sh.y[k] * g2[c];
      }
  }
  // A cell's merged sums are complete.
  void operator()(int64_t cell, const float* acc) {
    g.Add4(GridParam(cell, 0), acc[0], acc[1], acc[2], acc[3]);
    AddDiagFromRow(cell, acc + 4, g2, d);
    if (sh.degree > 0 && acc[4] != 0.f) AddBands(ShParam(sh.start, sh.degree, cell, 0, 0), acc[4]);
  }
  // The bands' J^T r and diagonal of a cell whose merged dc is `dc`, band block at `base` (a
  // multiple of 4): g and d interleave in fours (AddSink shift 1, offsets 0 and 4), so the
  // block's sums are one run of 2 stride floats; the degree-1 stride as a constant (vector adds).
  void AddBands(int64_t base, float dc) {
    float* b = g.a + (base << 1);
    const float dc2 = dc * dc;
    const auto add = [&](int stride) {
      for (int j = 0; j < stride; j += 4)
        for (int l = 0; l < 4; ++l) {
          b[2 * j + l] += dc * yr[j + l];
          b[2 * j + 4 + l] += dc2 * yg2[j + l];
        }
    };
    if (ShStride(sh.degree) == ShStride(1)) add(ShStride(1));
    else add(ShStride(sh.degree));
  }
  void Finish() {
    if constexpr (kDiag) merger.Finish(*this);
  }
};

// Records a ray's partials without scattering anything.
struct RecordOnly {
  BlockJ* row;
  void Shell(int k, const CubeCoord<float>& c, const TexelSample<float>&, const ShellPartials<float>& sp) {
    row->shells[k] = {c, sp};
  }
  void Sample(int, const MarchStep<float>& st, const GridSample<float>&, const SamplePartials<float>& sp) {
    row->samples.push_back({st.t, sp});
  }
};

// The photo slots the level's rays read (RaySet::exposure_slot: the exposures' and the poses'),
// checked against `count` photos, or nullptr when the level solves none (count 0).
const int32_t* PhotoSlots(const LevelProblem& p, int count);

// Bytes of the Jacobian record of `p`'s rays (every p.jtj_ray_stride-th), in blocks of
// `block_rays` rays (an estimate made by marching the rays, on the arena of `vectors`).
int64_t RecordedJacobianBytes(const LevelProblem& p, int64_t block_rays, bool compact, const CpuVectors& vectors);

}  // namespace perf::recon::cpu
