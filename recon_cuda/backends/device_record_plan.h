// How much of a level's Jacobian record the CUDA backend keeps (ray_record.h), planned on the
// host from the level's rays, so that the plan is built and tested without a GPU.
#pragma once

#include <cstdint>

#include "recon_cuda/core/compact_record.h"
#include "recon_cuda/core/ray_record.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

struct DeviceRecordPlan {
  static constexpr int64_t kEntryBytes = sizeof(CompactSampleJ) + sizeof(uint8_t);  // partials, step
  int64_t slots = 0;       // rays of the largest subset J^T J p multiplies (LevelProblem::jtj_ray_stride)
  int64_t wanted = 0;      // entries the subset's rays may need: their marches' steps and fillers
  int64_t capacity = 0;    // entries kept; 0: nothing is recorded (J^T J p recomputes every ray)
  int64_t slot_bytes = 0;  // a ray's head, and its H (exposures) and pose row (poses) where solved

  int64_t Bytes() const { return capacity > 0 ? capacity * kEntryBytes + slots * slot_bytes : 0; }
  int64_t WantedBytes() const { return wanted * kEntryBytes + slots * slot_bytes; }
  // Some rays may find no room (J^T J p recomputes those).
  bool Partial() const { return capacity > 0 && capacity < wanted; }
};

// The record of level p in `room` bytes: all of it where it fits, else as many entries as fit,
// but none when that is less than an eighth of it. `wanted` is estimated from a share of the
// level's rays through their pixel centres: each one's march (a sparse level's steps in stored
// bricks), ended where the level's start (LevelProblem::start, when given) turns opaque, plus
// half as much again for what the solve and the jitter change; without a start, whole marches
// (a bound) and 2 %.
DeviceRecordPlan PlanDeviceRecord(const LevelProblem& p, int64_t room);

}  // namespace perf::recon
