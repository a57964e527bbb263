#include "recon_cuda/backends/cpu_jacobian_record.h"

#include <tbb/parallel_for.h>

#include <algorithm>

#include "common/errors.h"
#include "recon_cuda/backends/cpu_vectors.h"

namespace perf::recon::cpu {

// Bytes of the recorded Jacobian: every ray's march length (no jitter needed for the count;
// early termination only shortens it; a sparse grid's march counted sample by sample, plus an
// eighth for the jittered samples that land differently, on every 4th ray of a block and scaled
// to the block: an estimate, and a quarter of a march) times the per-sample record, plus the
// shell records and, when poses are refined, the pose rows; of the recorded rays (every
// p.jtj_ray_stride-th) only.
void BlockJ::Clear(int64_t rays, const VolumeShape& shape, bool compact_samples) {
  compact = compact_samples;
  samples.clear();
  packed.clear();
  steps.clear();
  first_k.assign(compact ? rays : 0, 0);
  end.assign(rays, 0);
  shells.assign(compact ? 0 : rays * shape.num_shells, ShellJ{{-1, 0.f, 0.f}, {}});
  t_box.assign(compact ? rays : 0, 0.f);
  h.assign(3 * rays, 0.f);
  scale.assign(rays, 1.f);
  dl_per_delta.assign(compact ? rays : 0, 0.f);
  pose.assign(shape.poses > 0 && !compact ? kPoseRowValues * rays : 0, 0.f);
  packed_pose.assign(shape.poses > 0 && compact ? kPoseRowValues * rays : 0, 0);
}

void BlockJ::StorePose(int64_t r, const PoseRow<float>& row) {
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < kPoseSolved; ++j) {
      const size_t at = kPoseRowValues * r + kPoseSolved * i + j;
      if (compact) packed_pose[at] = ToBfloat16(row.j[i][j]);
      else pose[at] = row.j[i][j];
    }
  }
}

PoseRow<float> BlockJ::PoseAt(int64_t r) const {
  PoseRow<float> row;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < kPoseSolved; ++j) {
      const size_t at = kPoseRowValues * r + kPoseSolved * i + j;
      row.j[i][j] = compact ? FromBfloat16(packed_pose[at]) : pose[at];
    }
    for (int j = kPoseSolved; j < kPoseValues; ++j) row.j[i][j] = 0;
  }
  return row;
}

namespace {
// The fillers between a ray's entry at last_k (-1: none) and its next sample k < last_k: one every
// kMaxStep steps back, so that no step is longer.
int FillersBetween(int last_k, int k) { return last_k < 0 ? 0 : (last_k - k - 1) / CompactSampleJ::kMaxStep; }
}  // namespace

void BlockJ::AppendCompact(int64_t r, int k, const SamplePartials<float>& p, int* last_k) {
  auto at = static_cast<uint32_t>(packed.size());
  const int fillers = FillersBetween(*last_k, k);
  packed.resize(at + 1 + fillers);
  steps.resize(at + 1 + fillers);
  EncodeCompact(r, k, CompactSampleJ::Make(p), &at, last_k);
}

void BlockJ::EncodeCompact(int64_t r, int k, CompactSampleJ e, uint32_t* at, int* last_k) {
  PERF_CHECK(k >= 0 && k <= 0xffff && (*last_k < 0 || k < *last_k));
  for (int f = FillersBetween(*last_k, k); f > 0; --f, ++*at) {
    packed[*at] = CompactSampleJ::Filler();
    steps[*at] = CompactSampleJ::kMaxStep;
    *last_k -= CompactSampleJ::kMaxStep;
  }
  if (*last_k < 0) {
    first_k[r] = static_cast<uint16_t>(k);
    *last_k = k;
  }
  packed[*at] = e;
  steps[*at] = static_cast<uint8_t>(*last_k - k);
  ++*at;
  *last_k = k;
}

const int32_t* PhotoSlots(const LevelProblem& p, int count) {
  if (count == 0) return nullptr;
  PERF_CHECK_MSG(p.rays->exposure_slot.size() == p.rays->cameras.size(), "photo slots for every camera");
  for (int32_t slot : p.rays->exposure_slot) PERF_CHECK(slot >= 0 && slot < count);
  return p.rays->exposure_slot.data();
}

int64_t RecordedJacobianBytes(const LevelProblem& p, int64_t block_rays, bool compact, const CpuVectors& vectors) {
  constexpr int64_t kSparseStride = 4;
  const VolumeView<float> vol = MakeView(p.shape, p.geometry, nullptr);
  const int64_t n = p.rays->size();
  std::vector<int64_t> per_block((n + block_rays - 1) / block_rays, 0);
  vectors.arena().execute([&] {
    tbb::parallel_for(int64_t{0}, static_cast<int64_t>(per_block.size()), [&](int64_t b) {
      int64_t count = 0, sparse_count = 0, sparse_rays = 0;
      const int64_t begin = b * block_rays, end = std::min(n, (b + 1) * block_rays);
      for (int64_t i = begin; i < end; i += vol.brick_slot ? kSparseStride : 1) {
        const RayPixel& px = p.rays->pixels[i];
        const BoxRay<float> ray = PixelBoxRay(p.rays->cameras[px.camera], p.geometry.box, p.shape.n, px.x, px.y,
                                              Jitter{0, 0, false, false});
        const March<float> march = MakeMarch(vol, ray);
        if (!vol.brick_slot) {
          count += march.count;
          continue;
        }
        const Jitter none{0, 0, false, false};
        MarchStep<float> st;
        int taken = 0;
        for (int k = TakeSample(vol, ray, march, 0, 1, none, &st); k < march.count;
             k = TakeSample(vol, ray, march, k + 1, 1, none, &st)) {
          ++taken;
        }
        sparse_count += std::min(march.count, taken + taken / 8 + 2);
        ++sparse_rays;
      }
      if (sparse_rays > 0) count += (sparse_count * (end - begin) + sparse_rays - 1) / sparse_rays;
      per_block[b] = count;
    });
  });
  int64_t samples = 0;
  for (int64_t c : per_block) samples += c;
  // Only every jtj_ray_stride-th ray is recorded.
  const int64_t stride = std::max(1, p.jtj_ray_stride), recorded = (n + stride - 1) / stride;
  // What BlockJ keeps for a sample and for a recorded ray (the vectors of Clear).
  const size_t per_sample = compact ? sizeof(CompactSampleJ) + sizeof(uint8_t) : sizeof(SampleJ);  // packed, steps
  size_t per_ray = sizeof(uint32_t) + 4 * sizeof(float);                     // end, h, scale
  if (compact) per_ray += 2 * sizeof(float) + sizeof(uint16_t);  // dl_per_delta, t_box, first_k
  if (!compact) per_ray += p.shape.num_shells * sizeof(ShellJ);    // shells
  if (p.shape.poses > 0) per_ray += kPoseRowValues * (compact ? sizeof(uint16_t) : sizeof(float));  // the pose rows
  return samples / stride * static_cast<int64_t>(per_sample) + recorded * static_cast<int64_t>(per_ray);
}

}  // namespace perf::recon::cpu
