// Compile check: instantiates the per-ray forward and backward for float in a kernel so that CI
// compiles the host/device headers with nvcc even on machines without a GPU.
#include "recon_cuda/ray_math.h"

namespace perf::recon {
namespace {

struct AtomicScatter {
  float* grad;  // [ParamCount]
  float r[4];   // this ray's residuals
  __device__ void operator()(int64_t index, float dr, float dg, float db, float dl) {
    atomicAdd(grad + index, dr * r[0] + dg * r[1] + db * r[2] + dl * r[3]);
  }
};

// cams: [n_rays]; targets: [n_rays, 3]; grad: [ParamCount], J^T r accumulated.
__global__ void JtrCheckKernel(VolumeView<float> vol, BoxFrame<float> box, const PinholeCamera<float>* cams,
                               const float* targets, int n_rays, uint32_t seed, float lambda, float* grad) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n_rays) return;
  Vec3<float> o, d;
  PixelRay(cams[i], i % 7, i / 7, Uniform01<float>(seed, i, 0xfffffffeu), Uniform01<float>(seed, i, 0xffffffffu),
           &o, &d);
  const BoxRay<float> ray = ToBoxRay(box, vol.n, o, d);
  const Jitter jit{seed, static_cast<uint32_t>(i), true};
  const RayOutput<float> out = Forward(vol, ray, jit, targets + 3 * i, lambda);
  AtomicScatter visit{grad, {out.residual[0], out.residual[1], out.residual[2], out.residual[3]}};
  BackwardPerParam(vol, ray, jit, lambda, out, visit);
}

}  // namespace

void LaunchRayMathCheck(VolumeView<float> vol, BoxFrame<float> box, const PinholeCamera<float>* cams,
                        const float* targets, int n_rays, uint32_t seed, float lambda, float* grad) {
  if (n_rays <= 0) return;
  JtrCheckKernel<<<(n_rays + 127) / 128, 128>>>(vol, box, cams, targets, n_rays, seed, lambda, grad);
}

}  // namespace perf::recon
