// The Jacobian of one ray, used without ever forming it: J_ray p (a gather), J_ray^T u (a
// scatter) and the ray's exact contribution to diag(J^T J), all from the per-sample and per-shell
// partials that Backward (ray_math.h) hands to its visitor. Host and device: the CPU and CUDA
// backends differ only in the sink that receives the scattered values (plain adds into a
// per-thread buffer, or atomics).
//
// A sink has  Add4(int64_t index, T a, T b, T c, T d): adds to x[index .. index + 3].
#pragma once

#include "recon_cuda/ray_math.h"

namespace perf::recon {

// u[4] += J_sample p: p is a parameter-sized vector; the sample's cells are interpolated exactly
// as the volume is (p enters J p linearly through the same weights).
template <class T, class P>
PERF_HD_INLINE void AddJpSample(const P* p, const GridSample<T>& gs, const SamplePartials<T>& sp, T u[4]) {
  T pb[4] = {0, 0, 0, 0};
  for (int q = 0; q < 8; ++q) {
    const P* c = p + GridParam(gs.cell[q], 0);
    for (int ch = 0; ch < 4; ++ch) pb[ch] += gs.w[q] * static_cast<T>(c[ch]);
  }
  for (int c = 0; c < 3; ++c) u[c] += sp.dc * pb[c] + sp.ds[c] * pb[3];
  u[3] += sp.dl * pb[3];
}

template <class T, class P>
PERF_HD_INLINE void AddJpShell(const P* p, const TexelSample<T>& ts, const ShellPartials<T>& sp, T u[4]) {
  T pb[4] = {0, 0, 0, 0};
  for (int q = 0; q < 4; ++q) {
    for (int ch = 0; ch < 4; ++ch) pb[ch] += ts.w[q] * static_cast<T>(p[ts.param[q] + ch]);
  }
  for (int c = 0; c < 3; ++c) u[c] += sp.de * pb[c] + (sp.opaque ? T(0) : sp.da[c] * pb[3]);
}

// J_sample^T u into the sink: cell channel c gets w dc u_c, sigma gets w (sum_c ds_c u_c + dl u_L).
// With u = the ray's residuals this is the ray's share of the gradient J^T r.
template <class T, class Sink>
PERF_HD_INLINE void ScatterJtuSample(const GridSample<T>& gs, const SamplePartials<T>& sp, const T u[4], Sink& sink) {
  const T c0 = sp.dc * u[0], c1 = sp.dc * u[1], c2 = sp.dc * u[2];
  const T s = sp.ds[0] * u[0] + sp.ds[1] * u[1] + sp.ds[2] * u[2] + sp.dl * u[3];
  for (int q = 0; q < 8; ++q) {
    const T w = gs.w[q];
    sink.Add4(GridParam(gs.cell[q], 0), w * c0, w * c1, w * c2, w * s);
  }
}

template <class T, class Sink>
PERF_HD_INLINE void ScatterJtuShell(const TexelSample<T>& ts, const ShellPartials<T>& sp, const T u[4], Sink& sink) {
  const T c0 = sp.de * u[0], c1 = sp.de * u[1], c2 = sp.de * u[2];
  const T a = sp.opaque ? T(0) : sp.da[0] * u[0] + sp.da[1] * u[1] + sp.da[2] * u[2];
  for (int q = 0; q < 4; ++q) {
    const T w = ts.w[q];
    sink.Add4(ts.param[q], w * c0, w * c1, w * c2, w * a);
  }
}

// The ray's exact share of diag(J^T J): for every parameter, sum over the 4 residuals of the
// square of the SUMMED row entry. Squaring each (sample, cell) contribution on its own would
// drop the cross terms between neighbouring samples that share a cell (typically 3-5 samples
// do), understating the diagonal by up to that factor.
//
// Merging is cheap because the samples that reach one cell are consecutive: a cell's trilinear
// support is a box (clamping at the border keeps it one), a ray meets a box in one interval, and
// the samples are ordered along the ray. So only the previous sample's cells can still be
// reached; a cell of the previous sample that the current one does not reach is complete and is
// flushed. Texels of a shell are reached by one lookup per ray, so they only merge repeats at
// the face border.
template <class T>
class DiagMerger {
 public:
  template <class Sink>
  PERF_HD_INLINE void Sample(const GridSample<T>& gs, const SamplePartials<T>& sp, Sink& sink) {
    int64_t cell[8];
    T col[8], sig[8][4];
    int count = 0;
    for (int q = 0; q < 8; ++q) {
      int j = 0;
      while (j < count && cell[j] != gs.cell[q]) ++j;
      if (j == count) {
        cell[j] = gs.cell[q];
        col[j] = 0;
        for (int r = 0; r < 4; ++r) sig[j][r] = 0;
        ++count;
      }
      const T w = gs.w[q];
      col[j] += w * sp.dc;
      for (int r = 0; r < 3; ++r) sig[j][r] += w * sp.ds[r];
      sig[j][3] += w * sp.dl;
    }
    for (int i = 0; i < count_; ++i) {
      int j = 0;
      while (j < count && cell[j] != cell_[i]) ++j;
      if (j == count) {
        Flush(i, sink);
        continue;
      }
      col[j] += col_[i];
      for (int r = 0; r < 4; ++r) sig[j][r] += sig_[i][r];
    }
    for (int j = 0; j < count; ++j) {
      cell_[j] = cell[j];
      col_[j] = col[j];
      for (int r = 0; r < 4; ++r) sig_[j][r] = sig[j][r];
    }
    count_ = count;
  }

  // Call once per ray after the last sample.
  template <class Sink>
  PERF_HD_INLINE void Finish(Sink& sink) {
    for (int i = 0; i < count_; ++i) Flush(i, sink);
    count_ = 0;
  }

  template <class Sink>
  PERF_HD_INLINE static void Shell(const TexelSample<T>& ts, const ShellPartials<T>& sp, Sink& sink) {
    for (int q = 0; q < 4; ++q) {
      bool seen = false;
      for (int j = 0; j < q; ++j) seen = seen || ts.param[j] == ts.param[q];
      if (seen) continue;
      T w = 0;
      for (int j = q; j < 4; ++j) w += ts.param[j] == ts.param[q] ? ts.w[j] : T(0);
      const T c = w * sp.de;
      const T a = sp.opaque ? T(0) : w * w * (sp.da[0] * sp.da[0] + sp.da[1] * sp.da[1] + sp.da[2] * sp.da[2]);
      sink.Add4(ts.param[q], c * c, c * c, c * c, a);
    }
  }

 private:
  template <class Sink>
  PERF_HD_INLINE void Flush(int i, Sink& sink) {
    const T c = col_[i] * col_[i];
    const T s = sig_[i][0] * sig_[i][0] + sig_[i][1] * sig_[i][1] + sig_[i][2] * sig_[i][2] + sig_[i][3] * sig_[i][3];
    sink.Add4(GridParam(cell_[i], 0), c, c, c, s);
  }

  int64_t cell_[8];
  T col_[8], sig_[8][4];
  int count_ = 0;
};

}  // namespace perf::recon
