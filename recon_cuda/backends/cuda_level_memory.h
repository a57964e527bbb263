// What a level holds on the device besides the solver's vectors (cuda_backend.cc): its training
// rays, the passes' scratch and the Jacobian record, each with one owner (DeviceBuffer). Host
// code, internal to the CUDA backend.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "common/errors.h"
#include "recon_cuda/backends/cuda_kernels.h"
#include "recon_cuda/backends/device_buffer.h"
#include "recon_cuda/backends/device_record_plan.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon::cuda {

static_assert(sizeof(RayPixel) == 8, "RayPixel is copied to the device as is");

// Device bytes of the level's training rays: cameras, pixels, 8-bit colours and, when the level
// fits the alpha (UsesAlpha), 8-bit alphas.
inline int64_t RayBytes(const LevelProblem& p) {
  return static_cast<int64_t>(p.rays->cameras.size() * (sizeof(PinholeCamera<float>) + sizeof(int32_t))) +
         p.rays->size() * static_cast<int64_t>(sizeof(RayPixel) + 3 + (UsesAlpha(p) ? 1 : 0));
}

// Values in [0, 1] as the device stores them (ColourToByte).
inline std::vector<uint8_t> ToBytes(const std::vector<float>& values) {
  std::vector<uint8_t> bytes(values.size());
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = ColourToByte(values[i]);
  return bytes;
}

// The level's rays on the device (one owner: the backend, for one level).
struct DeviceRays {
  DeviceBuffer<PinholeCamera<float>> cameras;
  DeviceBuffer<RayPixel> pixels;
  DeviceBuffer<uint8_t> colours;
  DeviceBuffer<uint8_t> alphas;  // empty when the level has no alpha residual
  // Each camera's photo slot (RaySet::exposure_slot); empty when the level solves neither
  // exposures nor poses.
  DeviceBuffer<int32_t> exposure_slot;
  int64_t first_index = 0;       // RaySet::first_index
  bool exposures = false, poses = false;

  DeviceRays(const RaySet& rays, bool use_alpha, int num_exposures, int num_poses)
      : cameras(static_cast<int64_t>(rays.cameras.size())),
        pixels(rays.size()),
        colours(3 * rays.size()),
        alphas(use_alpha ? rays.size() : 0),
        exposure_slot(num_exposures > 0 || num_poses > 0 ? static_cast<int64_t>(rays.cameras.size()) : 0),
        first_index(rays.first_index),
        exposures(num_exposures > 0),
        poses(num_poses > 0) {
    PERF_CHECK(static_cast<int64_t>(rays.colours.size()) == 3 * rays.size());
    cameras.CopyFromHost(rays.cameras);
    pixels.CopyFromHost(rays.pixels);
    colours.CopyFromHost(ToBytes(rays.colours));
    if (use_alpha) alphas.CopyFromHost(ToBytes(rays.alphas));
    if (exposures || poses) {
      PERF_CHECK(rays.exposure_slot.size() == rays.cameras.size());
      for (int32_t slot : rays.exposure_slot) {
        PERF_CHECK(slot >= 0 && (!exposures || slot < num_exposures) && (!poses || slot < num_poses));
      }
      exposure_slot.CopyFromHost(rays.exposure_slot);
    }
  }
  RaysView View() const {
    return {cameras.data(),
            pixels.data(),
            colours.data(),
            alphas.size() > 0 ? alphas.data() : nullptr,
            pixels.size(),
            first_index,
            exposures ? exposure_slot.data() : nullptr,
            poses ? exposure_slot.data() : nullptr};
  }
};

// Render draws an image in bands of at most this many pixels through buffers allocated with the
// level (16 MiB), so that its memory is part of the level's estimate whatever the image size.
constexpr int64_t kRenderBandPixels = int64_t{1} << 20;

// Pass statistics, reductions' working memory and Render's band.
struct Scratch {
  DeviceBuffer<RayStats> partials, total;
  DeviceBuffer<double> result;
  DeviceBuffer<uint8_t> temp;
  DeviceBuffer<float> render_colour, render_opacity;  // [kRenderBandPixels, 3], [kRenderBandPixels]

  static int64_t Bytes(int64_t rays, int64_t params) {
    const int64_t blocks = PassBlocks(rays);
    return (blocks + 1) * static_cast<int64_t>(sizeof(RayStats)) + static_cast<int64_t>(sizeof(double)) +
           static_cast<int64_t>(std::max(StatsTempBytes(blocks), ReduceTempBytes(params))) +
           4 * kRenderBandPixels * static_cast<int64_t>(sizeof(float));
  }
  Scratch(int64_t rays, int64_t params)
      : partials(std::max<int64_t>(PassBlocks(rays), 1)),
        total(1),
        result(1),
        temp(static_cast<int64_t>(std::max(StatsTempBytes(PassBlocks(rays)), ReduceTempBytes(params)))),
        render_colour(3 * kRenderBandPixels),
        render_opacity(kRenderBandPixels) {}
  StatsScratch Stats() {
    return {partials.data(), partials.size(), total.data(), temp.data(), static_cast<size_t>(temp.size())};
  }
  ReduceScratch Reduce() { return {result.data(), temp.data(), static_cast<size_t>(temp.size())}; }
};

// The Jacobian record of a level (ray_record.h) on the device, as DeviceRecordPlan sizes it.
struct DeviceRecord {
  DeviceBuffer<CompactSampleJ> packed;
  DeviceBuffer<uint8_t> steps;
  DeviceBuffer<RayRecordHead> heads;
  DeviceBuffer<float> h;         // with exposures
  DeviceBuffer<uint16_t> pose;   // with poses
  DeviceBuffer<unsigned long long> used;

  DeviceRecord(const DeviceRecordPlan& plan, const VolumeShape& shape)
      : packed(plan.capacity),
        steps(plan.capacity),
        heads(plan.slots),
        h(shape.exposures > 0 ? 3 * plan.slots : 0),
        pose(shape.poses > 0 ? kPoseRowValues * plan.slots : 0),
        used(1) {}
  // The record of the rays of jtj.
  RecordView View(RaySubset jtj) {
    return {packed.data(), steps.data(),  packed.size(),
            used.data(),   heads.data(),  h.size() > 0 ? h.data() : nullptr,
            pose.size() > 0 ? pose.data() : nullptr, jtj.stride, jtj.offset};
  }
};

}  // namespace perf::recon::cuda
