// The CPU backend's per-ray sinks and the Jacobian record that Linearize keeps for MultiplyJtJ
// (cpu_backend.cc): the partials of every sample and shell of every ray, block by block. Internal
// to the CPU backend.
#pragma once

#include <cstdint>
#include <vector>

#include "common/errors.h"
#include "recon_cuda/backends/cpu_backend.h"
#include "recon_cuda/backends/record_arena.h"
#include "recon_cuda/core/compact_record.h"
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

// How Linearize records the Jacobian: exactly (SampleJ), compactly sample by sample
// (CompactSampleJ), or compactly with each ray's cells merged (MergedCellJ).
enum class RecordKind { kExact, kCompact, kMerged };

// One sample of a ray's Jacobian as the exact record keeps it; the compact record keeps
// CompactSampleJ (compact_record.h) instead.
struct SampleJ {
  float t;
  SamplePartials<float> sp;
};
// One cell of a ray's merged record (BlockJ::merged): what the ray's samples put on that cell,
// summed over them with their trilinear weights (RayCells' K = sum_j w_jq (dc, ds[3], dl)_j,
// as Linearize's merge makes it for the diagonal), in float: J^T J p is then the exact record's
// but for the order of sums, and reads and writes each cell once per ray, with no march step, no
// trilinear weights and no brick lookup. In bfloat16 (16 bytes) solver_bounds_test's free system
// was solved to 1.4 % instead of 1 %: one rounding of a cell's sum errs more than the samples'
// independent ones.
struct MergedCellJ {
  uint32_t cell;
  float k[5];
};
static_assert(sizeof(MergedCellJ) == 24, "24 bytes a merged cell of a ray");
struct ShellJ {
  CubeCoord<float> coord;  // face -1: the ray misses this shell
  ShellPartials<float> sp;
};

// The recorded Jacobian of one block of rays.
struct BlockJ {
  bool compact = false;                 // its samples are in `packed` and `steps`, else in `samples`
  bool merged = false;                  // compact, and its rays' cells in `cells` (no samples)
  std::vector<SampleJ> samples;
  ArenaVector<MergedCellJ> cells;  // its room from the level's arena (record_arena.h), where Clear is given one
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

  // Empty, for `rays` rays of a level of `shape`, kept as `kind`, with room for `entries` samples
  // (merged: cells), so that the first Linearize of a level does not copy them as they grow; the
  // merged cells' room from `arena` where one is given.
  void Clear(int64_t rays, const VolumeShape& shape, RecordKind kind = RecordKind::kExact, int64_t entries = 0,
             RecordArena* arena = nullptr);
  // One past the last sample (merged: cell) recorded.
  uint32_t SampleCount() const {
    return static_cast<uint32_t>(merged ? cells.size() : compact ? packed.size() : samples.size());
  }
  // Ray r's pose row, stored and read back (rounded to bfloat16 when compact).
  void StorePose(int64_t r, const PoseRow<float>& row);
  PoseRow<float> PoseAt(int64_t r) const;
  // Compact: appends sample k of ray r (its partials), which lies before the ray's sample last_k
  // (-1: the ray's first entry); last_k becomes k.
  void AppendCompact(int64_t r, int k, const SamplePartials<float>& p, int* last_k);
  // Compact: compact_record.h EncodeCompact of sample k of ray r at entry *at of the block.
  void EncodeCompact(int64_t r, int k, CompactSampleJ e, uint32_t* at, int* last_k);
};

// vol: at the linearisation point (the compact record recomputes the shells' lookups and values
// there, as Backward made them: the same partials to the bit).
inline void RecordedShells(const BlockJ& b, int64_t r, const VolumeView<float>& vol, const BoxRay<float>& ray,
                           const March<float>& m, RayShellsJ* out) {
  const int n = vol.num_shells;
  if (b.compact) {
    CompactShells(vol, ray, m, b.t_box[r], out);
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
      : b_(b),
        m_(m),
        jit_(jit),
        j_(first),
        compact_(b.compact && !b.merged
                     ? CompactReader{b.packed.data(), b.steps.data(), b.first_k[r], b.dl_per_delta[r]}
                     : CompactReader{nullptr, nullptr, 0, 0.f}) {}
  // The next sample's t; its partials into *sp.
  float Next(SamplePartials<float>* sp) {
    const uint32_t j = j_++;
    if (!b_.compact) {
      *sp = b_.samples[j].sp;
      return b_.samples[j].t;
    }
    return compact_.Next(j, m_, jit_, sp);
  }
  int k() const { return compact_.k; }  // the march index of the last sample read (compact)

 private:
  const BlockJ& b_;
  const March<float>& m_;
  const Jitter& jit_;
  uint32_t j_;
  CompactReader compact_;
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

// Drops, in place, the merged cells that reach no free parameter with a non-zero value: merged
// dc 0 (every sample's colour terms vanish there) and the cell's density held (SkippableSample).
inline void DropSkippableCells(const float* free, BlockJ* block) {
  uint32_t first = 0, kept = 0;
  for (size_t r = 0; r < block->end.size(); ++r) {
    for (uint32_t j = first; j < block->end[r]; ++j) {
      const MergedCellJ& c = block->cells[j];
      if (c.k[0] == 0.f && free[GridParam(c.cell, 3)] == 0.f) continue;
      block->cells[kept++] = c;
    }
    first = block->end[r];
    block->end[r] = kept;
  }
  block->cells.resize(kept);
}

// The photo slots the level's rays read (RaySet::exposure_slot: the exposures' and the poses'),
// checked against `count` photos, or nullptr when the level solves none (count 0).
const int32_t* PhotoSlots(const LevelProblem& p, int count);

// What a level's Jacobian record holds (every p.jtj_ray_stride-th ray): its samples, its rays'
// cells as a merged record keeps them (counted only with count_cells; up to where a ray turns
// opaque in p.start when the level has one), and its rays. An estimate made by marching the rays
// of each block of `block_rays` without jitter (a sparse grid's or the cells on every 4th ray, an
// eighth added for the jittered samples that land differently), on the arena of `vectors`.
struct RecordEstimate {
  int64_t samples = 0, cells = 0, rays = 0;
  std::vector<int64_t> block_samples, block_cells;  // [blocks]
};
RecordEstimate EstimateRecord(const LevelProblem& p, int64_t block_rays, const CpuVectors& vectors, bool count_cells);
// Bytes of that record, kept as `kind`.
int64_t RecordBytes(const RecordEstimate& e, RecordKind kind, const VolumeShape& shape);

// A level's memory on a backend of `threads` threads and `options`, and the record Linearize keeps
// for it: the options' kind, except that merged cells (4 to 5 a sample, 24 bytes each, against 9
// bytes a sample) are kept only without spherical harmonics and when the level fits in half the
// memory with them; else its samples (docs/tuning.md "Merged cells"). kept: bytes the backend holds
// for the record from the level before (RecordArena), counted as available.
struct LevelPlan {
  MemoryEstimate memory;
  RecordKind record = RecordKind::kCompact;
  std::vector<int64_t> entries;  // [blocks] the record's estimated entries (BlockJ::Clear); empty: none
  // The room a merged record's blocks reserve together in the level's RecordArena (0: samples).
  size_t ArenaBytes() const;
};
LevelPlan PlanLevel(const LevelProblem& p, int num_vectors, int threads, const CpuBackendOptions& options,
                    int64_t block_rays, const CpuVectors& vectors, size_t kept);

}  // namespace perf::recon::cpu
