// The compact form of one ray's recorded Jacobian, shared by the CPU backend's record
// (cpu_jacobian_record.h BlockJ) and the CUDA backend's device record (ray_record.h): each sample's
// four colour and density partials in bfloat16 plus one byte, the march steps back to the ray's
// entry before; per ray the march index of its first entry, dL/dsigma per unit step and T_box, from
// which its samples' positions, dl and its shells' partials are recomputed exactly as Backward
// made them. Host and device.
#pragma once

#include <stdint.h>

#include "recon_cuda/core/pose.h"
#include "recon_cuda/core/ray_math.h"

#ifndef __CUDA_ARCH__
#include <bit>
#endif

namespace perf::recon {

// A float rounded to bfloat16 (its top 16 bits, to nearest, ties to even), and back.
PERF_HD_INLINE uint16_t ToBfloat16(float x) {
#ifdef __CUDA_ARCH__
  uint32_t u = __float_as_uint(x);
#else
  uint32_t u = std::bit_cast<uint32_t>(x);
#endif
  u += 0x7fffu + ((u >> 16) & 1u);
  return static_cast<uint16_t>(u >> 16);
}
PERF_HD_INLINE float FromBfloat16(uint16_t h) {
#ifdef __CUDA_ARCH__
  return __uint_as_float(static_cast<uint32_t>(h) << 16);
#else
  return std::bit_cast<float>(static_cast<uint32_t>(h) << 16);
#endif
}

// One sample of a ray's Jacobian, compact: its colour and density partials (dc, ds[3]) in
// bfloat16 (8 bits of mantissa) and, apart, one byte: how many march steps it lies before the
// ray's entry before (records run back to front), so its march index, whose t and delta StepAt
// recomputes exactly (9 bytes a sample). Its dl is the ray's DlPerDelta times delta, as Backward
// makes it, so it is not stored; it is rounded to bfloat16 as the others are, so that the product
// is the 12-byte record's to the bit (left exact, the two-rank MPI test's cost bound failed;
// docs/tuning.md "dl not recorded"). A gap of more than kMaxStep steps between two samples of a
// ray is bridged by fillers: entries whose partials are all 0, dl too, which add exact zeros.
struct CompactSampleJ {
  static constexpr int kMaxStep = 255;
  static constexpr uint16_t kFiller = 0xffff;  // sp[0] of a filler (a bfloat16 NaN)
  uint16_t sp[4];                              // dc, ds[3]
  PERF_HD_INLINE static CompactSampleJ Make(const SamplePartials<float>& p) {
    return {{ToBfloat16(p.dc), ToBfloat16(p.ds[0]), ToBfloat16(p.ds[1]), ToBfloat16(p.ds[2])}};
  }
  PERF_HD_INLINE static CompactSampleJ Filler() { return {{kFiller, 0, 0, 0}}; }
  PERF_HD_INLINE bool IsFiller() const { return sp[0] == kFiller; }
  PERF_HD_INLINE SamplePartials<float> Partials(float dl) const {
    if (IsFiller()) return {0.f, {0.f, 0.f, 0.f}, 0.f};
    return {FromBfloat16(sp[0]), {FromBfloat16(sp[1]), FromBfloat16(sp[2]), FromBfloat16(sp[3])}, dl};
  }
};
static_assert(sizeof(CompactSampleJ) == 8, "8 bytes of partials a recorded sample, and its step");

// The fillers between a ray's entry at last_k (-1: none) and its next sample k < last_k: one every
// kMaxStep steps back, so that no step is longer.
PERF_HD_INLINE int FillersBetween(int last_k, int k) {
  return last_k < 0 ? 0 : (last_k - k - 1) / CompactSampleJ::kMaxStep;
}
// The most entries a ray whose samples lie at march indices below `end` can need: its samples
// and the fillers of its gaps (together at most end - 1 steps long, hence (end - 1) / kMaxStep).
PERF_HD_INLINE int MaxCompactEntries(int samples, int end) {
  return samples + (end > 0 ? (end - 1) / CompactSampleJ::kMaxStep : 0);
}

// Writes entry e, sample k of a ray, at packed[*at] and steps[*at] (and fillers before it where
// needed), after the ray's sample last_k (-1: none; then k becomes *first_k); *at moves past it and
// last_k becomes k. In place over the ray's own entries when some are dropped: it never writes past
// the entry it is given. k must lie in [0, 0xffff] and below last_k.
PERF_HD_INLINE void EncodeCompact(CompactSampleJ* packed, uint8_t* steps, int k, CompactSampleJ e, uint32_t* at,
                                  int* last_k, uint16_t* first_k) {
  for (int f = FillersBetween(*last_k, k); f > 0; --f, ++*at) {
    packed[*at] = CompactSampleJ::Filler();
    steps[*at] = CompactSampleJ::kMaxStep;
    *last_k -= CompactSampleJ::kMaxStep;
  }
  if (*last_k < 0) {
    *first_k = static_cast<uint16_t>(k);
    *last_k = k;
  }
  packed[*at] = e;
  steps[*at] = static_cast<uint8_t>(*last_k - k);
  ++*at;
  *last_k = k;
}

// Reads one ray's compact entries back in their order (its last sample first): entry j's
// position t on the ray and its partials. march and jit: the ray's (MakeMarch, its Jitter).
struct CompactReader {
  const CompactSampleJ* packed;  // [the ray's entries]
  const uint8_t* steps;          // [the ray's entries]
  int k;                         // the march index of the entry read last (first: the ray's first_k)
  float dl_per_delta;            // the ray's DlPerDelta

  PERF_HD_INLINE float Next(uint32_t j, const March<float>& m, const Jitter& jit, SamplePartials<float>* sp) {
    k -= steps[j];
    const MarchStep<float> st = StepAt(m, k, jit);
    *sp = packed[j].Partials(FromBfloat16(ToBfloat16(dl_per_delta * st.delta)));
    return st.t;
  }
};

// A recorded ray's shells as J^T J p reads them: which the ray meets, their texel weights and
// partials.
struct RayShellsJ {
  bool hit[kMaxShells];
  TexelSample<float> ts[kMaxShells];
  ShellPartials<float> sp[kMaxShells];
};
// A compact record's shells: where the ray meets them and their values at the linearisation
// point vol (as Backward looked them up), their partials from the ray's box transmittance t_box
// (ray_math.h ShellPartialsAt): the same partials to the bit.
PERF_HD_INLINE void CompactShells(const VolumeView<float>& vol, const BoxRay<float>& ray, const March<float>& m,
                                  float t_box, RayShellsJ* out) {
  const int n = vol.num_shells;
  ShellStack<float> st;
  EvalShells(vol, ray, m, &st, out->ts);
  float behind[3] = {0.f, 0.f, 0.f};
  for (int k = n - 1; k >= 0; --k) {
    out->hit[k] = st.hit[k];
    if (!st.hit[k]) continue;
    out->sp[k] = ShellPartialsAt(st, k, n, t_box, behind);
  }
}

// A ray's pose row (pose.h PoseRow) without its padding column: 4 residuals x 7 values, and the
// row in bfloat16 (the compact records' form) and back.
inline constexpr int kPoseRowValues = 4 * kPoseSolved;
PERF_HD_INLINE void PackPoseRow(const PoseRow<float>& row, uint16_t* out) {  // out: [kPoseRowValues]
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < kPoseSolved; ++j) out[kPoseSolved * i + j] = ToBfloat16(row.j[i][j]);
}
PERF_HD_INLINE PoseRow<float> UnpackPoseRow(const uint16_t* packed) {  // packed: [kPoseRowValues]
  PoseRow<float> row;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < kPoseSolved; ++j) row.j[i][j] = FromBfloat16(packed[kPoseSolved * i + j]);
    for (int j = kPoseSolved; j < kPoseValues; ++j) row.j[i][j] = 0;
  }
  return row;
}

}  // namespace perf::recon
