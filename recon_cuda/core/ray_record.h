// The CUDA backend's Jacobian record (cuda_passes.cu): the partials of the recorded rays of one
// Gauss-Newton iteration, written by Linearize and read by every J^T J p of that iteration, so
// that a product reads 9 bytes a sample and gathers p instead of marching the volume three times
// (Forward, then Backward twice; on an H100 that ran at a fifteenth of the cost pass's rate per
// sample: docs/tuning.md "Second GPU run"). Each ray's entries are the compact record's
// (compact_record.h), contiguous from an offset handed out while Linearize runs (a warp at a
// time on the device); a ray for which no room is left is not recorded, and J^T J p recomputes
// that ray. Views over flat arrays, host and device: the kernels run this code, and
// ray_record_test runs the same code on the host against the CPU backend's record.
#pragma once

#include <stdint.h>

#include "recon_cuda/core/compact_record.h"
#include "recon_cuda/core/jacobian.h"
#include "recon_cuda/core/pose.h"
#include "recon_cuda/core/training_ray.h"

namespace perf::recon {

// One recorded ray.
struct RayRecordHead {
  int64_t first;       // its first entry in RecordView::packed and steps; -1: not recorded
  uint32_t count;      // its entries (samples and fillers)
  uint16_t first_k;    // the march index of its first entry (its last sample)
  uint16_t unused;
  float dl_per_delta;  // ray_math.h DlPerDelta
  float t_box;         // its box transmittance, for its shells' partials (CompactShells)
  float scale;         // the robust loss's row scale (jacobian.h RobustRowScale)
  float unused2;
};
static_assert(sizeof(RayRecordHead) == 32, "32 bytes a recorded ray");

// The record of the rays offset, offset + stride, ... (backend.h RaySubset) of a pass; ray i of
// that subset has slot i / stride.
struct RecordView {
  CompactSampleJ* packed = nullptr;    // [capacity]
  uint8_t* steps = nullptr;            // [capacity]
  int64_t capacity = 0;                // entries
  unsigned long long* used = nullptr;  // entries handed out; may pass capacity (then no ray gets more)
  RayRecordHead* heads = nullptr;      // [slots]; nullptr: nothing is recorded
  float* h = nullptr;                  // [slots, 3] H at the linearisation point, when exposures are solved
  uint16_t* pose = nullptr;            // [slots, kPoseRowValues] the pose rows, when poses are refined
  int stride = 1, offset = 0;

  PERF_HD_INLINE bool Records(int64_t i) const { return heads != nullptr && i % stride == offset; }
  PERF_HD_INLINE int64_t Slot(int64_t i) const { return i / stride; }
};

// The entries a ray may write (its samples and the most fillers they can need), to reserve before
// its Backward sweep.
PERF_HD_INLINE uint32_t EntriesToReserve(const RayOutput<float>& fwd) {
  return static_cast<uint32_t>(MaxCompactEntries(fwd.count, fwd.end));
}

// Hands out `need` entries from rec.used one ray after another: the first, or -1 when they do not
// fit (the device hands them out a warp at a time: cuda_passes.cu ReserveEntries).
inline int64_t ReserveInOrder(const RecordView& rec, uint32_t need) {
  const unsigned long long first = *rec.used;
  *rec.used += need;
  return first + need <= static_cast<unsigned long long>(rec.capacity) ? static_cast<int64_t>(first) : -1;
}

// Linearize's part: a ray's entries as Backward visits its samples (call Sample from the visitor's
// Sample), from entry `first` of the record (-1: the ray is not recorded, nothing is written).
struct RecordWriter {
  CompactSampleJ* packed = nullptr;
  uint8_t* steps = nullptr;
  uint32_t at = 0;
  int last_k = -1;
  uint16_t first_k = 0;

  PERF_HD_INLINE void Begin(const RecordView& rec, int64_t first) {
    packed = first >= 0 ? rec.packed + first : nullptr;
    steps = first >= 0 ? rec.steps + first : nullptr;
    at = 0;
    last_k = -1;
    first_k = 0;
  }
  PERF_HD_INLINE void Sample(int k, const SamplePartials<float>& sp) {
    if (packed) EncodeCompact(packed, steps, k, CompactSampleJ::Make(sp), &at, &last_k, &first_k);
  }
};

// After the ray's Backward sweep: its head, H and pose row (row: nullptr when its pose is not
// refined) in the slot of ray i; first: its entries' (RecordWriter::Begin).
PERF_HD_INLINE void FinishRecord(const RecordView& rec, int64_t i, int64_t first, const RecordWriter& w,
                                 const RayOutput<float>& fwd, float scale, const PoseRow<float>* row) {
  const int64_t s = rec.Slot(i);
  rec.heads[s] = {first, w.at, w.first_k, 0, DlPerDelta(fwd), fwd.t_box, scale, 0.f};
  if (first < 0) return;
  if (rec.h)
    for (int c = 0; c < 3; ++c) rec.h[3 * s + c] = fwd.h[c];
  if (rec.pose && row) PackPoseRow(*row, rec.pose + kPoseRowValues * s);
}

// A recorded ray's exposure (jacobian.h ExposureOfRay) from its H and row scale; slot: its
// photo's exposure slot (-1: none solved); xf: its photo's colour transform at the linearisation
// point.
PERF_HD_INLINE RayExposure<float> RecordedExposure(const RecordView& rec, int64_t i, int64_t exposure_start,
                                                   int slot, const ColourTransform<float>& xf) {
  const int64_t s = rec.Slot(i);
  const float none[3] = {0.f, 0.f, 0.f};
  return ExposureOfRay(exposure_start, slot, xf, rec.h ? rec.h + 3 * s : none, rec.heads[s].scale);
}

// J^T u on a ray's samples, merged cell by cell along the ray (jacobian.h CellMerger): one Add4 a
// cell a ray (and its bands, with spherical harmonics).
template <class Sink>
struct MergedScatter {
  float u[4];
  Sink& sink;
  RaySh<float> sh;
  CellMerger<float, 4> merger{};

  PERF_HD_INLINE void Sample(const GridSample<float>& gs, const SamplePartials<float>& sp) {
    float v[4];
    JtuValues(sp, u, v);
    merger.Sample(gs, v, *this);
  }
  PERF_HD_INLINE void operator()(int64_t cell, const float* acc) {
    sink.Add4(GridParam(cell, 0), acc[0], acc[1], acc[2], acc[3]);
    if (sh.degree > 0) ScatterSh(sh, cell, acc, sink);
  }
  PERF_HD_INLINE void Finish() { merger.Finish(*this); }
};

// J_ray^T J_ray p of recorded ray i (r: the ray as the linearisation's passes saw it; e: its
// RecordedExposure, vol: the linearisation point): J p gathered from its entries, shells and pose
// row, then J^T (J p) scattered: the volume's entries into `sink` (merged by cell), the exposure's
// into `exposure`, the pose's into `pose`. free: backend.h RestrictJacobian's mask, or nullptr.
// Returns the samples used.
template <class Sink, class ExposureSink, class PoseSink>
PERF_HD int RecordedJtJp(const RecordView& rec, int64_t i, const VolumeView<float>& vol, const TrainingRay& r,
                         const RayExposure<float>& e, const float* p, const float* free, Sink& sink,
                         ExposureSink& exposure, PoseSink& pose) {
  const int64_t s = rec.Slot(i);
  const RayRecordHead head = rec.heads[s];
  const March<float> m = MakeMarch(vol, r.ray);
  const RaySh<float> sh = ShOfRay(vol, r.ray);
  RayShellsJ shells;
  CompactShells(vol, r.ray, m, head.t_box, &shells);
  float u[4] = {0.f, 0.f, 0.f, 0.f};
  for (int k = 0; k < vol.num_shells; ++k) {
    if (shells.hit[k]) AddJpShell(p, shells.ts[k], shells.sp[k], u);
  }
  // Entry j's cells, or false where it adds nothing (a filler, or a sample free lets us skip).
  const auto sample = [&](CompactReader& read, uint32_t j, GridSample<float>* gs, SamplePartials<float>* sp) {
    const float t = read.Next(j, m, r.jit, sp);
    if (read.packed[j].IsFiller()) return false;
    *gs = TrilinearWeights(vol.n, vol.brick_slot, r.ray.GridPoint(t));
    return !(free && SkippableSample(*gs, *sp, free));
  };
  const CompactSampleJ* packed = rec.packed + head.first;
  const uint8_t* steps = rec.steps + head.first;
  int used = 0;
  CompactReader read{packed, steps, head.first_k, head.dl_per_delta};
  for (uint32_t j = 0; j < head.count; ++j) {
    GridSample<float> gs;
    SamplePartials<float> sp;
    if (!sample(read, j, &gs, &sp)) continue;
    AddJpSample(p, gs, sp, u, sh);
    ++used;
  }
  PoseRow<float> row;
  const bool posed = r.pose >= 0 && rec.pose;
  if (posed) {
    row = UnpackPoseRow(rec.pose + kPoseRowValues * s);
    AddJpPose(row, p, r.pose, u);
  }
  FinishJp(e, p, u);
  MergedScatter<Sink> scatter{{0.f, 0.f, 0.f, 0.f}, sink, sh};
  VolumeU(e, u, scatter.u);
  for (int k = 0; k < vol.num_shells; ++k) {
    if (shells.hit[k]) ScatterJtuShell(shells.ts[k], shells.sp[k], scatter.u, sink);
  }
  CompactReader again{packed, steps, head.first_k, head.dl_per_delta};
  for (uint32_t j = 0; j < head.count; ++j) {
    GridSample<float> gs;
    SamplePartials<float> sp;
    if (sample(again, j, &gs, &sp)) scatter.Sample(gs, sp);
  }
  scatter.Finish();
  ScatterJtuExposure(e, u, exposure);
  if (posed) ScatterJtuPose(row, r.pose, scatter.u, pose);
  return used;
}

}  // namespace perf::recon
