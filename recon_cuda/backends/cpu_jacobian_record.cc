#include "recon_cuda/backends/cpu_jacobian_record.h"

#include <tbb/parallel_for.h>

#include <algorithm>

#include "common/errors.h"
#include "common/system_memory.h"
#include "recon_cuda/backends/cpu_vectors.h"

namespace perf::recon::cpu {

void BlockJ::Clear(int64_t rays, const VolumeShape& shape, RecordKind kind, int64_t entries, RecordArena* arena) {
  compact = kind != RecordKind::kExact;
  merged = kind == RecordKind::kMerged;
  samples.clear();
  if (cells.get_allocator().arena != arena) cells = ArenaVector<MergedCellJ>(ArenaAllocator<MergedCellJ>(arena));
  cells.clear();
  packed.clear();
  steps.clear();
  const auto reserve = static_cast<size_t>(std::max<int64_t>(entries, 0));
  if (merged) {
    cells.reserve(reserve);
  } else if (compact) {
    packed.reserve(reserve);
    steps.reserve(reserve);
  } else {
    samples.reserve(reserve);
  }
  first_k.assign(compact && !merged ? rays : 0, 0);
  end.assign(rays, 0);
  shells.assign(compact ? 0 : rays * shape.num_shells, ShellJ{{-1, 0.f, 0.f}, {}});
  t_box.assign(compact ? rays : 0, 0.f);
  h.assign(3 * rays, 0.f);
  scale.assign(rays, 1.f);
  dl_per_delta.assign(compact && !merged ? rays : 0, 0.f);
  pose.assign(shape.poses > 0 && !compact ? kPoseRowValues * rays : 0, 0.f);
  packed_pose.assign(shape.poses > 0 && compact ? kPoseRowValues * rays : 0, 0);
}

void BlockJ::StorePose(int64_t r, const PoseRow<float>& row) {
  if (compact) {
    PackPoseRow(row, &packed_pose[kPoseRowValues * r]);
    return;
  }
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < kPoseSolved; ++j) pose[kPoseRowValues * r + kPoseSolved * i + j] = row.j[i][j];
}

PoseRow<float> BlockJ::PoseAt(int64_t r) const {
  if (compact) return UnpackPoseRow(&packed_pose[kPoseRowValues * r]);
  PoseRow<float> row;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < kPoseSolved; ++j) row.j[i][j] = pose[kPoseRowValues * r + kPoseSolved * i + j];
    for (int j = kPoseSolved; j < kPoseValues; ++j) row.j[i][j] = 0;
  }
  return row;
}

void BlockJ::AppendCompact(int64_t r, int k, const SamplePartials<float>& p, int* last_k) {
  auto at = static_cast<uint32_t>(packed.size());
  const int fillers = FillersBetween(*last_k, k);
  packed.resize(at + 1 + fillers);
  steps.resize(at + 1 + fillers);
  EncodeCompact(r, k, CompactSampleJ::Make(p), &at, last_k);
}

void BlockJ::EncodeCompact(int64_t r, int k, CompactSampleJ e, uint32_t* at, int* last_k) {
  PERF_CHECK(k >= 0 && k <= 0xffff && (*last_k < 0 || k < *last_k));
  recon::EncodeCompact(packed.data(), steps.data(), k, e, at, last_k, &first_k[r]);
}

const int32_t* PhotoSlots(const LevelProblem& p, int count) {
  if (count == 0) return nullptr;
  PERF_CHECK_MSG(p.rays->exposure_slot.size() == p.rays->cameras.size(), "photo slots for every camera");
  for (int32_t slot : p.rays->exposure_slot) PERF_CHECK(slot >= 0 && slot < count);
  return p.rays->exposure_slot.data();
}

namespace {
// How many of a sample's cells its predecessor on the ray (prev) did not reach: the cells a
// ray's merged record gains with it (CellMerger emits a cell once it leaves the samples' window).
int NewCells(const GridSample<float>& gs, const GridSample<float>& prev, bool first) {
  int count = 0;
  for (int q = 0; q < 8; ++q) {
    if (gs.cell[q] < 0) continue;
    bool seen = false;
    for (int j = 0; j < 8 && !first && !seen; ++j) seen = prev.cell[j] == gs.cell[q];
    if (!seen) ++count;
  }
  return count;
}
}  // namespace

RecordEstimate EstimateRecord(const LevelProblem& p, int64_t block_rays, const CpuVectors& vectors, bool count_cells) {
  // With the level's start, the cells are counted up to where a ray turns opaque (as Linearize
  // records them); the samples are a march's whole length either way (what the compact record
  // may grow to).
  const bool opaque_ends = count_cells && !p.start.empty() && p.residuals.stop_transmittance > 0;
  PERF_CHECK(p.start.empty() || static_cast<int64_t>(p.start.size()) == p.shape.ParamCount());
  const VolumeView<float> vol = MakeView(p.shape, p.geometry, opaque_ends ? p.start.data() : nullptr);
  const float stop = p.residuals.stop_transmittance;
  const int64_t n = p.rays->size();
  struct Counts {
    int64_t samples = 0, cells = 0;
  };
  std::vector<Counts> per_block((n + block_rays - 1) / block_rays);
  vectors.arena().execute([&] {
    tbb::parallel_for(int64_t{0}, static_cast<int64_t>(per_block.size()), [&](int64_t b) {
      int64_t samples = 0, cells = 0, rays = 0;
      const int64_t begin = b * block_rays, end = std::min(n, (b + 1) * block_rays);
      // A dense grid's samples are its march's length, counted on every ray; a sparse march and
      // the cells are walked sample by sample on every 4th ray.
      const int64_t step = vol.brick_slot || count_cells ? 4 : 1;
      for (int64_t i = begin; i < end; i += step, ++rays) {
        const RayPixel& px = p.rays->pixels[i];
        const Jitter none{0, 0, false, false};
        const BoxRay<float> ray = PixelBoxRay(p.rays->cameras[px.camera], p.geometry.box, p.shape.n, px.x, px.y, none);
        const March<float> march = MakeMarch(vol, ray);
        if (!vol.brick_slot && !count_cells) {
          samples += march.count;
          continue;
        }
        MarchStep<float> st;
        int taken = 0, new_cells = 0;
        float trans = 1;
        GridSample<float> prev{};
        for (int k = TakeSample(vol, ray, march, 0, 1, none, &st); k < march.count;
             k = TakeSample(vol, ray, march, k + 1, 1, none, &st)) {
          if (count_cells && trans >= stop) {
            const GridSample<float> gs = TrilinearWeights(vol.n, vol.brick_slot, ray.GridPoint(st.t));
            new_cells += NewCells(gs, prev, taken == 0);
            prev = gs;
            if (opaque_ends) {
              float v[4];
              GatherGrid(vol.params, gs, v);
              trans *= Exp(-v[3] * st.delta);
            }
          }
          ++taken;
        }
        // An eighth more for the jittered samples that land differently.
        samples += vol.brick_slot ? std::min(march.count, taken + taken / 8 + 2) : march.count;
        cells += new_cells + new_cells / 8;
      }
      const auto scaled = [&](int64_t count) { return (count * (end - begin) + rays - 1) / rays; };
      if (rays > 0) per_block[b] = {scaled(samples), scaled(cells)};
    });
  });
  // Only every jtj_ray_stride-th ray is recorded.
  const int64_t stride = std::max(1, p.jtj_ray_stride);
  RecordEstimate e;
  for (const Counts& c : per_block) {
    e.block_samples.push_back(c.samples / stride);
    e.block_cells.push_back(c.cells / stride);
    e.samples += c.samples / stride;
    e.cells += c.cells / stride;
  }
  e.rays = (n + stride - 1) / stride;
  return e;
}

int64_t RecordBytes(const RecordEstimate& e, RecordKind kind, const VolumeShape& shape) {
  const bool merged = kind == RecordKind::kMerged, compact = kind != RecordKind::kExact;
  // What BlockJ keeps for a sample (merged: for a cell of a ray) and for a recorded ray (the
  // vectors of Clear).
  const int64_t entries = merged ? e.cells : e.samples;
  const size_t per_entry = merged    ? sizeof(MergedCellJ)
                           : compact ? sizeof(CompactSampleJ) + sizeof(uint8_t)  // packed, steps
                                     : sizeof(SampleJ);
  size_t per_ray = sizeof(uint32_t) + 4 * sizeof(float);                // end, h, scale
  if (compact) per_ray += sizeof(float);                                // t_box
  if (compact && !merged) per_ray += sizeof(float) + sizeof(uint16_t);  // dl_per_delta, first_k
  if (!compact) per_ray += shape.num_shells * sizeof(ShellJ);           // shells
  if (shape.poses > 0) per_ray += kPoseRowValues * (compact ? sizeof(uint16_t) : sizeof(float));  // the pose rows
  return entries * static_cast<int64_t>(per_entry) + e.rays * static_cast<int64_t>(per_ray);
}

size_t LevelPlan::ArenaBytes() const {
  if (record != RecordKind::kMerged) return 0;
  size_t bytes = 0;
  for (int64_t cells : entries) bytes += RecordArena::Rounded(cells * sizeof(MergedCellJ));
  return bytes;
}

LevelPlan PlanLevel(const LevelProblem& p, int num_vectors, int threads, const CpuBackendOptions& options,
                    int64_t block_rays, const CpuVectors& vectors, size_t kept) {
  MemoryEstimate e;
  const int64_t params = p.shape.ParamCount();
  e.vectors = num_vectors * params * 4;
  e.scratch = int64_t{threads} * 2 * params * 4;
  e.rays = p.rays ? p.rays->Bytes() : 0;
  const auto available = AvailableMemory() + static_cast<int64_t>(kept);
  e.available = options.max_memory > 0 ? options.max_memory : available * 9 / 10;
  RecordKind kind = !options.compact_jacobian                               ? RecordKind::kExact
                    : options.merged_jacobian && p.shape.sh_degree == 0 ? RecordKind::kMerged
                                                                        : RecordKind::kCompact;
  if (options.cache_jacobian && p.rays) {
    const bool merged = kind == RecordKind::kMerged;
    const RecordEstimate r = EstimateRecord(p, block_rays, vectors, merged);
    if (merged && e.available > 0 && 2 * (e.Needed() + RecordBytes(r, RecordKind::kMerged, p.shape)) > e.available) {
      kind = RecordKind::kCompact;
    }
    e.jacobian_cache = RecordBytes(r, kind, p.shape);
    return {e, kind, kind == RecordKind::kMerged ? r.block_cells : r.block_samples};
  }
  return {e, kind, {}};
}

}  // namespace perf::recon::cpu
