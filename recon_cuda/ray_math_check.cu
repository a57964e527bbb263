// Compile check: instantiates the per-ray forward, the backward sweep and the Jacobian helpers of
// jacobian.h (merged J^T r + exact diagonal, J p, J^T u) for float in kernels, so that CI compiles
// the host/device headers with nvcc even on machines without a GPU. Never launched by the tests:
// the CUDA backend proper (issue 4) will replace it.
#include "recon_cuda/jacobian.h"

namespace perf::recon {
namespace {

struct AtomicSink {
  float* a;
  __device__ void Add4(int64_t i, float x, float y, float z, float w) {
    atomicAdd(a + i, x);
    atomicAdd(a + i + 1, y);
    atomicAdd(a + i + 2, z);
    atomicAdd(a + i + 3, w);
  }
};

// J^T r and diag(J^T J) with the per-ray cell merge, as a GPU Linearize would do them.
struct LinearizeCheck {
  float r[4];
  AtomicSink g, d;
  CellMerger<float, 9> merger;
  __device__ void Shell(int, const CubeCoord<float>&, const TexelSample<float>& ts, const ShellPartials<float>& sp) {
    ScatterJtuShell(ts, sp, r, g);
    AddDiagShell(ts, sp, d);
  }
  __device__ void Sample(int, const MarchStep<float>&, const GridSample<float>& gs, const SamplePartials<float>& sp) {
    float v[9];
    JtuValues(sp, r, v);
    RowValues(sp, v + 4);
    merger.Sample(gs, v, *this);
  }
  __device__ void operator()(int64_t cell, const float* acc) {
    g.Add4(GridParam(cell, 0), acc[0], acc[1], acc[2], acc[3]);
    AddDiagFromRow(cell, acc + 4, d);
  }
};

// J p into u (gather), then J^T u (scatter), recomputing the partials: the recompute path.
struct JpCheck {
  const float* p;
  float u[4];
  __device__ void Shell(int, const CubeCoord<float>&, const TexelSample<float>& ts, const ShellPartials<float>& sp) {
    AddJpShell(p, ts, sp, u);
  }
  __device__ void Sample(int, const MarchStep<float>&, const GridSample<float>& gs, const SamplePartials<float>& sp) {
    AddJpSample(p, gs, sp, u);
  }
};
struct JtuCheck {
  const float* u;
  AtomicSink out;
  __device__ void Shell(int, const CubeCoord<float>&, const TexelSample<float>& ts, const ShellPartials<float>& sp) {
    ScatterJtuShell(ts, sp, u, out);
  }
  __device__ void Sample(int, const MarchStep<float>&, const GridSample<float>& gs, const SamplePartials<float>& sp) {
    ScatterJtuSample(gs, sp, u, out);
  }
};

__device__ BoxRay<float> CheckRay(const PinholeCamera<float>* cams, const BoxFrame<float>& box, int n, int i,
                                  uint32_t seed) {
  return PixelBoxRay(cams[i], box, n, i % 7, i / 7, Jitter{seed, static_cast<uint32_t>(i), true});
}

// cams: [n_rays]; targets: [n_rays, 3]; grad, diag: [ParamCount].
__global__ void LinearizeCheckKernel(VolumeView<float> vol, BoxFrame<float> box, const PinholeCamera<float>* cams,
                                     const float* targets, int n_rays, uint32_t seed, float lambda, float* grad,
                                     float* diag) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n_rays) return;
  const BoxRay<float> ray = CheckRay(cams, box, vol.n, i, seed);
  const Jitter jit{seed, static_cast<uint32_t>(i), true};
  const RayOutput<float> out = Forward(vol, ray, jit, targets + 3 * i, lambda, 1e-4f);
  LinearizeCheck v{{out.residual[0], out.residual[1], out.residual[2], out.residual[3]}, {grad}, {diag}, {}};
  Backward(vol, ray, jit, lambda, out, v);
  v.merger.Finish(v);
}

// p, out: [ParamCount]; out += J^T J p.
__global__ void JtJpCheckKernel(VolumeView<float> vol, BoxFrame<float> box, const PinholeCamera<float>* cams,
                                int n_rays, uint32_t seed, float lambda, const float* p, float* out) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n_rays) return;
  const BoxRay<float> ray = CheckRay(cams, box, vol.n, i, seed);
  const Jitter jit{seed, static_cast<uint32_t>(i), true};
  const float zero[3] = {0, 0, 0};
  const RayOutput<float> fwd = Forward(vol, ray, jit, zero, lambda, 1e-4f);
  JpCheck jp{p, {0, 0, 0, 0}};
  Backward(vol, ray, jit, lambda, fwd, jp);
  JtuCheck jtu{jp.u, {out}};
  Backward(vol, ray, jit, lambda, fwd, jtu);
}

}  // namespace

void LaunchRayMathCheck(VolumeView<float> vol, BoxFrame<float> box, const PinholeCamera<float>* cams,
                        const float* targets, int n_rays, uint32_t seed, float lambda, float* grad, float* diag,
                        const float* p, float* jtjp) {
  if (n_rays <= 0) return;
  const int blocks = (n_rays + 127) / 128;
  LinearizeCheckKernel<<<blocks, 128>>>(vol, box, cams, targets, n_rays, seed, lambda, grad, diag);
  JtJpCheckKernel<<<blocks, 128>>>(vol, box, cams, n_rays, seed, lambda, p, jtjp);
}

}  // namespace perf::recon
