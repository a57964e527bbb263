#include "recon_cuda/backends/device_record_plan.h"

#include <algorithm>

#include "common/errors.h"
#include "recon_cuda/core/ray_math.h"

namespace perf::recon {
namespace {

// The samples Linearize takes on a ray through the pixel centre: every march step of a dense
// level, the steps in stored bricks of a sparse one, and with the level's start (vol.params) only
// those before the ray turns opaque (transmittance below `stop`).
int SamplesOf(const VolumeView<float>& vol, const BoxRay<float>& ray, float stop) {
  const March<float> march = MakeMarch(vol, ray);
  if (!vol.brick_slot && !vol.params) return march.count;
  const Jitter none{0, 0, false, false};
  MarchStep<float> st;
  int taken = 0;
  float trans = 1;
  for (int k = TakeSample(vol, ray, march, 0, 1, none, &st); k < march.count;
       k = TakeSample(vol, ray, march, k + 1, 1, none, &st)) {
    ++taken;
    if (!vol.params) continue;
    float v[4];
    GatherGrid(vol.params, TrilinearWeights(vol.n, vol.brick_slot, ray.GridPoint(st.t)), v);
    trans *= Exp(-v[3] * st.delta);
    if (trans < stop) break;
  }
  return taken;
}

}  // namespace

DeviceRecordPlan PlanDeviceRecord(const LevelProblem& p, int64_t room) {
  DeviceRecordPlan plan;
  if (!p.rays || p.rays->size() == 0) return plan;
  const int64_t rays = p.rays->size();
  const int64_t stride = std::max(1, p.jtj_ray_stride);
  plan.slots = (rays + stride - 1) / stride;
  plan.slot_bytes = static_cast<int64_t>(sizeof(RayRecordHead)) + (p.shape.exposures > 0 ? 3 * sizeof(float) : 0) +
                    (p.shape.poses > 0 ? kPoseRowValues * sizeof(uint16_t) : 0);
  const bool opaque_ends = !p.start.empty() && p.residuals.stop_transmittance > 0;
  PERF_CHECK(p.start.empty() || static_cast<int64_t>(p.start.size()) == p.shape.ParamCount());
  const VolumeView<float> vol = MakeView(p.shape, p.geometry, opaque_ends ? p.start.data() : nullptr);
  // A dense march's length is a slab test: every 16th ray. Walking a march: about 2^18 rays.
  const bool walk = vol.brick_slot || opaque_ends;
  const int64_t every = walk ? std::max<int64_t>(16, rays >> 18) : 16;
  const Jitter none{0, 0, false, false};
  int64_t sampled = 0, entries = 0, whole = 0;
  for (int64_t i = 0; i < rays; i += every, ++sampled) {
    const RayPixel& px = p.rays->pixels[i];
    const BoxRay<float> ray = PixelBoxRay(p.rays->cameras[px.camera], p.geometry.box, p.shape.n, px.x, px.y, none);
    const int end = MakeMarch(vol, ray).count + 1;  // one step more for the jitter
    entries += MaxCompactEntries(std::min(end, SamplesOf(vol, ray, p.residuals.stop_transmittance) + 1), end);
    whole += MaxCompactEntries(end, end);
  }
  // Whole marches are a bound (2 % for the rays not sampled); rays ended where the start turns
  // opaque are a prediction (the level's densities move, the jitter moves the samples): half as
  // much again, but never more than the bound.
  const auto scaled = [&](int64_t count, double margin) {
    return static_cast<int64_t>(static_cast<double>(count) / static_cast<double>(sampled) * margin *
                                static_cast<double>(plan.slots)) + plan.slots;
  };
  plan.wanted = std::min(scaled(entries, opaque_ends ? 1.5 : 1.02), scaled(whole, 1.02));
  const int64_t fit = (room - plan.slots * plan.slot_bytes) / DeviceRecordPlan::kEntryBytes;
  plan.capacity = std::min(plan.wanted, std::max<int64_t>(fit, 0));
  if (plan.capacity < plan.wanted / 8) plan.capacity = 0;
  return plan;
}

}  // namespace perf::recon
