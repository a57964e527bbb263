// The CPU backend's per-ray passes over cells (cpu_backend.cc): Linearize's visitor, which scatters
// the gradient and diagonal and fills the Jacobian record (cpu_jacobian_record.h), and J^T J p on a
// ray's merged cells. Internal to the CPU backend.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "recon_cuda/backends/cpu_jacobian_record.h"
#include "recon_cuda/core/jacobian.h"
#include "recon_cuda/core/ray_math.h"

namespace perf::recon::cpu {

// What a pass over a block of rays adds up (cpu_backend.cc ForBlocks combines them in block order).
struct BlockStats {
  double cost = 0, colour_sse = 0, subset_cost = 0;
  int64_t rays = 0, samples = 0;
  void Add(const RayOutput<float>& o, float robust_scale, bool in_subset = false) {
    const RayCost c = CostOf(o, robust_scale);
    colour_sse += c.colour_sse;
    cost += c.cost;
    if (in_subset) subset_cost += c.cost;
    rays += 1;
    samples += o.count;
  }
};

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

// J p and J^T u of one recorded ray on its merged cells (BlockJ::merged, `count` of them from
// `c`), as RayCells computes them on the cells it merges. Degree 0 only: with spherical harmonics
// the bands' traffic dominates and re-merging the samples measured as fast (docs/tuning.md
// "Merged cells"), so those levels keep their samples.
struct MergedCells {
  const MergedCellJ* c;
  int count;

  static constexpr int kAhead = 8;  // cells whose line of p is asked for ahead of AddJp's
  // u += J p (RayCells::AddJp). The sums' lines are asked for on the way, for ScatterJtu.
  void AddJp(const float* p, float* sums, float u[4]) const {
    for (int j = 0; j < std::min(count, kAhead); ++j) __builtin_prefetch(p + GridParam(c[j].cell, 0));
    for (int j = 0; j < count; ++j) {
      if (j + kAhead < count) __builtin_prefetch(p + GridParam(c[j + kAhead].cell, 0));
      __builtin_prefetch(sums + GridParam(c[j].cell, 0), 1);
      const float* k = c[j].k;
      const float* g = p + GridParam(c[j].cell, 0);
      for (int ch = 0; ch < 3; ++ch) u[ch] += k[0] * g[ch] + k[1 + ch] * g[3];
      u[3] += k[4] * g[3];
    }
  }
  // sums += J^T uv (RayCells::ScatterJtu).
  void ScatterJtu(const float uv[4], float* sums) const {
    for (int j = 0; j < count; ++j) {
      const float* k = c[j].k;
      float* g = sums + GridParam(c[j].cell, 0);
      for (int ch = 0; ch < 3; ++ch) g[ch] += k[0] * uv[ch];
      g[3] += k[1] * uv[0] + k[2] * uv[1] + k[3] * uv[2] + k[4] * uv[3];
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
    if (!out || out->merged) return;  // merged: the cells are recorded as they are flushed
    if (out->compact) out->AppendCompact(out_ray, k, sp, &last_k);
    else out->samples.push_back({st.t, sp});
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
    if (out && out->merged) {
      out->cells.push_back({static_cast<uint32_t>(cell), {acc[4], acc[5], acc[6], acc[7], acc[8]}});
    }
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

}  // namespace perf::recon::cpu
