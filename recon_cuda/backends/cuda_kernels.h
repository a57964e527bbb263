// Launchers of the CUDA backend's kernels (cuda_passes.cu, cuda_vector_ops.cu). No CUDA types:
// cuda_backend.cc (g++) owns every buffer and calls these with device pointers. All launches go
// to the default stream, in order; the functions that return a host value synchronise.
//
// Memory choice (paper: 3D textures for hardware trilinear filtering, copied to linear memory
// for atomics). Here the parameters, J^T r, diag and J^T J p live in plain linear device memory
// and the gathers are ordinary global loads of the 8 cells (cached in L1/L2 like __ldg on
// Hopper), for three reasons: (1) every pass scatters with atomics into arrays of the same
// layout, which textures cannot receive, so a texture copy of x (and of p for J^T J p) would be
// needed after every update, i.e. several copies per Gauss-Newton iteration; (2) filtering
// hardware interpolates with 8-bit fixed-point weights, which would make the forward and the
// derivative (which needs the exact weights) inconsistent and break parity with the CPU;
// (3) the per-ray code is shared with the CPU and takes plain pointers. Unmeasured: no GPU has
// run this code yet; a texture path for the Cost pass alone would be the experiment to try.
#pragma once

#include <stddef.h>
#include <stdint.h>

#include <array>

#include "recon_cuda/core/param_ops.h"
#include "recon_cuda/core/ray_math.h"
#include "recon_cuda/core/ray_record.h"
#include "recon_cuda/core/smoothness.h"
#include "recon_cuda/core/training_ray.h"

namespace perf::recon::cuda {

// The training rays on the device (training_ray.h). Colours are 8-bit (value / 255): a quarter
// of float's memory and bandwidth; exact for 8-bit photos at full resolution, within 1/510 for
// the averaged pixels of the image pyramid (below the photos' own quantisation).
using RaysView = TrainingRays<uint8_t>;

// Everything a ray pass reads.
struct PassInput {
  VolumeView<float> vol;  // params: device pointer
  BoxFrame<float> box;
  RaysView rays;
  float lambda, stop_transmittance;
  bool jitter, pixel_jitter;
  uint32_t seed;
  float robust;  // ResidualSettings::robust_scale
};

// Statistics of one block of rays, summed in a fixed order (per block, then over blocks).
struct RayStats {
  double cost = 0, colour_sse = 0;
  long long rays = 0, samples = 0;
  double subset_cost = 0;  // Linearize: the cost of the rays i with i % stride == offset
};

// Working memory of the pass statistics: one RayStats per block of rays, the device-side sum
// and CUB's temporary storage.
struct StatsScratch {
  RayStats* partials;  // [capacity]
  int64_t capacity;    // blocks: PassBlocks(rays)
  RayStats* total;     // [1]
  void* temp;          // [temp_bytes]
  size_t temp_bytes;
};
int64_t PassBlocks(int64_t rays);
// CUB's temporary storage for summing `blocks` RayStats.
size_t StatsTempBytes(int64_t blocks);

// Passes (backend.h). Outputs are overwritten (zeroed first), not accumulated.
// g, diag: [ParamCount]; diag may be nullptr (Adam). pose_blocks: [poses, kPoseBlock] the
// photos' pose blocks (pose.h AddPoseBlock), needed with diag when the rays refine poses.
// rec: with diag, the Jacobian record (ray_record.h) the rays of its subset write (its counter
// zeroed first); rec.heads nullptr: none.
RayStats Linearize(const PassInput& in, float* g, float* diag, float* pose_blocks, const RecordView& rec,
                   int64_t params, int stride, int offset, const StatsScratch& s);
// The entries Linearize's rays asked rec for (more than rec.capacity: some rays found no room and
// were not recorded). Synchronises.
int64_t RecordedEntries(const RecordView& rec);
// out = J_S^T J_S p at in.vol (the linearisation point) and in.seed, S the rays offset, offset +
// stride, ...; p, out: [ParamCount]. free: nullptr, or the parameters the product is needed on
// (backend.h RestrictJacobian). rec: the last Linearize's record of S (rec.heads nullptr: none;
// every ray is recomputed); recompute_rest: some of its rays were not recorded (RecordedEntries)
// and are recomputed.
RayStats MultiplyJtJ(const PassInput& in, const float* p, const float* free, float* out, int64_t params, int stride,
                     int offset, const StatsScratch& s, const RecordView& rec = {}, bool recompute_rest = false);
// Rays offset, offset + stride, ... only.
RayStats Cost(const PassInput& in, int stride, int offset, const StatsScratch& s);
// Rows y0 .. y0 + rows - 1 of an image `width` pixels wide; colour: [rows, width, 3], opacity:
// [rows, width] (device), row y0 first.
void Render(const VolumeView<float>& vol, const BoxFrame<float>& box, const PinholeCamera<float>& camera, int width,
            int y0, int rows, float stop_transmittance, float min_box_opacity, float* colour, float* opacity);

// Vector operations on n floats (device pointers).
void Fill(float* y, int64_t n, float value);
void Copy(float* y, const float* x, int64_t n);
void Axpy(float* y, float a, const float* x, int64_t n);               // y += a x
void Xpby(float* y, const float* x, float b, int64_t n);               // y = x + b y
void DivideClamped(float* z, const float* r, const float* d, float floor, int64_t n);
void AxpyDiag(float* y, float a, const float* d, const float* x, int64_t n);  // y += a d x
// layout: where each part of the parameters starts (param_ops.h KindOfParam).
void Project(float* x, int64_t n, const ParamLayout& layout);
// backend.h HoldParameters and Multiply.
void HoldParameters(const float* x, float* g, float* free, int64_t n, const ParamLayout& layout,
                    const HeldKinds& held, bool bounds);
void Multiply(float* y, const float* m, int64_t n);
void AdamStep(float* x, const float* g, float* m, float* v, const AdamCoefficients& c, int64_t n,
              const ParamLayout& layout);

// Reductions in double with CUB (deterministic: a fixed tree for a given n and device).
struct ReduceScratch {
  double* result;  // [1]
  void* temp;      // [temp_bytes]
  size_t temp_bytes;
};
size_t ReduceTempBytes(int64_t n);
double Dot(const float* a, const float* b, int64_t n, const ReduceScratch& s);
double MaxAbs(const float* a, int64_t n, const ReduceScratch& s);
// backend.h AddSmoothness, SmoothnessCost (layout's tables on the device) and SumByKind.
void AddSmoothness(const float* v, const SmoothnessLayout& layout, const SmoothnessWeights& w, float* out, float* diag,
                   int64_t n);
double SmoothnessCost(const float* v, const SmoothnessLayout& layout, const SmoothnessWeights& w, int64_t n,
                      const ReduceScratch& s);
std::array<double, kParamKinds> SumByKind(const float* v, int64_t n, const ParamLayout& layout,
                                          const ReduceScratch& s);

// Whether the kernels of this build can run on the current device (a binary built for sm_90 +
// PTX does not run on older GPUs): nullptr if so, else the CUDA error's description.
const char* KernelImageError();

// Device memory the driver reserves for the ray kernels' local memory (stack frames: the cell
// merge buffers and per-shell arrays) once they run: the largest per-thread size of any of them
// (or the stack size limit, if larger) for every thread the current device can hold at once.
int64_t KernelLocalMemoryBytes();

// Training colours in [0, 1] to 8 bits, rounded to nearest (host side, before upload); values
// outside are clamped and NaN maps to 0 (a float-to-integer cast of NaN or of a value out of
// range is undefined behaviour, so the comparisons, written to be false for NaN, come first).
inline uint8_t ColourToByte(float c) {
  const float v = c > 0.f ? (c < 1.f ? c : 1.f) : 0.f;
  return static_cast<uint8_t>(v * 255.f + 0.5f);
}
// ColourToByte's inverse (training_ray.h ColourValue, as the passes read the rays).
PERF_HD_INLINE float ByteToColour(uint8_t b) { return ColourValue(b); }

}  // namespace perf::recon::cuda
