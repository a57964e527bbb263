// The Jacobian of one ray, used without ever forming it: J_ray p (a gather), J_ray^T u (a
// scatter) and the ray's exact contribution to diag(J^T J), all from the per-sample and per-shell
// partials that Backward (ray_math.h) hands to its visitor. Host and device: the CPU and CUDA
// backends differ only in the sink that receives the scattered values (plain adds into a
// per-thread buffer, or atomics).
//
// A sink has  Add4(int64_t index, T a, T b, T c, T d): adds to x[index .. index + 3].
#pragma once

#include "recon_cuda/core/ray_math.h"

namespace perf::recon {

// u[4] += J_sample p: p is a parameter-sized vector; the sample's cells are interpolated exactly
// as the volume is (p enters J p linearly through the same weights). sh: the ray's spherical
// harmonics (ray_math.h RaySh; degree 0: none), whose coefficients enter as the colour does, times y_k.
template <class T>
PERF_HD_INLINE void AddJpSample(const T* p, const GridSample<T>& gs, const SamplePartials<T>& sp, T u[4],
                                const RaySh<T>& sh) {
  T pb[4];
  GatherGrid(p, gs, pb);
  if (sh.degree > 0 && sp.dc != T(0)) AddShColour(p, sh, gs, pb);  // with dc = 0 the bands add 0 dc
  for (int c = 0; c < 3; ++c) u[c] += sp.dc * pb[c] + sp.ds[c] * pb[3];
  u[3] += sp.dl * pb[3];
}

// Adds y_k^power a[c] to band k, channel c of a cell's spherical harmonics, in groups of 4 (the
// padded stride, ray_types.h ShStride; the padding gets zeros).
template <class T, class Sink>
PERF_HD_INLINE void AddShBands(const RaySh<T>& sh, int64_t cell, const T* a, int power, Sink& sink) {
  const int stride = ShStride(sh.degree);
  T v[kMaxShStride];
  for (int i = 0; i < stride; ++i) v[i] = 0;
  for (int k = 0; k < sh.bands; ++k) {
    const T y = power == 2 ? sh.y[k] * sh.y[k] : sh.y[k];
    for (int c = 0; c < 3; ++c) v[3 * k + c] = y * a[c];
  }
  const int64_t base = sh.start + static_cast<int64_t>(stride) * cell;
  for (int i = 0; i < stride; i += 4) sink.Add4(base + i, v[i], v[i + 1], v[i + 2], v[i + 3]);
}

// The spherical harmonics' share of a cell's J^T u: colour[c] is what the cell's colour channel
// c receives (JtuValues times the weight, or their merged sum along the ray); band k of channel c
// receives y_k colour[c]. Nothing is written when colour is 0 (a sample or cell whose partial dc
// is 0, which the density's lower bound makes common: a third of the cells of a ray).
template <class T, class Sink>
PERF_HD_INLINE void ScatterSh(const RaySh<T>& sh, int64_t cell, const T* colour, Sink& sink) {
  if (colour[0] == T(0) && colour[1] == T(0) && colour[2] == T(0)) return;
  AddShBands(sh, cell, colour, 1, sink);
}

// The spherical harmonics' share of a cell's diag(J^T J) from its merged colour row entry dc (the
// ray's, RowValues): band k of channel c gets g_c^2 (y_k dc)^2.
template <class T, class Sink>
PERF_HD_INLINE void AddDiagSh(const RaySh<T>& sh, int64_t cell, T dc, const T* g2, Sink& sink) {
  if (dc == T(0)) return;  // zeros (ScatterSh)
  const T sq[3] = {g2[0] * dc * dc, g2[1] * dc * dc, g2[2] * dc * dc};
  AddShBands(sh, cell, sq, 2, sink);
}

template <class T>
PERF_HD_INLINE void AddJpShell(const T* p, const TexelSample<T>& ts, const ShellPartials<T>& sp, T u[4]) {
  T pb[4];
  GatherTexels(p, ts, pb);
  for (int c = 0; c < 3; ++c) u[c] += sp.de * pb[c] + (sp.opaque ? T(0) : sp.da[c] * pb[3]);
}

// Whether J^T J p may skip a sample once it is needed only on the free parameters, for p that is
// 0 on the held ones (backend.h RestrictJacobian; free: 1 free, 0 held). With dc = T_i alpha_i = 0
// (the sample's cells have density 0) it adds exact zeros to every colour of J p and J^T u; with
// its 8 cells' densities all held, its density terms of J p (ds, dl times p's zeros) vanish and
// what it scatters to them is masked away.
template <class T>
PERF_HD_INLINE bool SkippableSample(const GridSample<T>& gs, const SamplePartials<T>& sp, const float* free) {
  if (sp.dc != T(0)) return false;
  for (int q = 0; q < 8; ++q) {
    if (gs.cell[q] >= 0 && free[GridParam(gs.cell[q], 3)] != 0.f) return false;
  }
  return true;
}

// The 4 values a sample contributes, times its trilinear weight, to each of its cells in
// J^T u: colour channel c gets dc u_c, sigma gets sum_c ds_c u_c + dl u_L.
template <class T>
PERF_HD_INLINE void JtuValues(const SamplePartials<T>& sp, const T u[4], T* v) {
  v[0] = sp.dc * u[0];
  v[1] = sp.dc * u[1];
  v[2] = sp.dc * u[2];
  v[3] = sp.ds[0] * u[0] + sp.ds[1] * u[1] + sp.ds[2] * u[2] + sp.dl * u[3];
}

// J_sample^T u into the sink (JtuValues times each cell's weight). With u = the ray's residuals
// this is the ray's share of the gradient J^T r.
template <class T, class Sink>
PERF_HD_INLINE void ScatterJtuSample(const GridSample<T>& gs, const SamplePartials<T>& sp, const T u[4], Sink& sink,
                                     const RaySh<T>& sh) {
  T v[4];
  JtuValues(sp, u, v);
  for (int q = 0; q < 8; ++q) {
    if (gs.cell[q] < 0) continue;  // an inactive brick's cell: no parameter
    const T w = gs.w[q];
    sink.Add4(GridParam(gs.cell[q], 0), w * v[0], w * v[1], w * v[2], w * v[3]);
    if (sh.degree > 0) {
      const T colour[3] = {w * v[0], w * v[1], w * v[2]};
      ScatterSh(sh, gs.cell[q], colour, sink);
    }
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

// Merging the per-sample contributions of one ray cell by cell before they reach memory.
//
// The samples that reach one cell are consecutive: a cell's trilinear support is a box (clamping
// at the border keeps it one), a ray meets a box in one interval, and the samples are ordered
// along the ray. So only the previous sample's cells can still be reached; a cell of the
// previous sample that the current one does not reach is complete and is flushed once.
//
// Two uses. (1) diag(J^T J) must square the SUMMED row entry of each parameter; squaring each
// (sample, cell) contribution on its own would drop the cross terms between the 3-5 samples that
// share a cell. (2) Scatters (J^T r, J^T u) write each cell once per ray instead of once per
// sample: fewer dependent read-modify-writes on the CPU, fewer atomics on the GPU.
//
// CellMerger<T, K> accumulates, per cell, K sums of w * v[k] (w: the sample's trilinear weight of
// that cell, v: the sample's K values) and calls flush(cell, const T acc[K]) when a cell is done;
// never for a cell of an inactive brick (-1), whose sums are dropped.
template <class T, int K>
class CellMerger {
 public:
  template <class Flush>
  PERF_HD_INLINE void Sample(const GridSample<T>& gs, const T (&v)[K], Flush& flush) {
    if (gs.distinct && distinct_) {
      // Both samples have 8 distinct cells at lo + {0,1}^3: corner q of this sample is corner
      // q + (lo - lo_prev) of the previous one when that lies in {0,1}^3.
      const int d0 = gs.lo[0] - lo_[0], d1 = gs.lo[1] - lo_[1], d2 = gs.lo[2] - lo_[2];
      if (d0 == 0 && d1 == 0 && d2 == 0) {  // the same cells: accumulate in place
        for (int q = 0; q < 8; ++q)
          for (int k = 0; k < K; ++k) acc_[q][k] += gs.w[q] * v[k];
        return;
      }
      T next[8][K];
      bool used[8] = {false, false, false, false, false, false, false, false};
      for (int q = 0; q < 8; ++q) {
        const int px = (q & 1) + d0, py = ((q >> 1) & 1) + d1, pz = (q >> 2) + d2;
        const bool shared = (px == 0 || px == 1) && (py == 0 || py == 1) && (pz == 0 || pz == 1);
        const int p = px + 2 * py + 4 * pz;
        for (int k = 0; k < K; ++k) next[q][k] = gs.w[q] * v[k] + (shared ? acc_[p][k] : T(0));
        if (shared) used[p] = true;
      }
      for (int p = 0; p < 8; ++p) {
        if (!used[p]) Emit(flush, cell_[p], acc_[p]);
      }
      Store(gs, next, 8);
      return;
    }
    // General case (a border sample, or the ray's first): merge by cell index.
    int64_t cell[8];
    T acc[8][K];
    int count = 0;
    for (int q = 0; q < 8; ++q) {
      int j = 0;
      while (j < count && cell[j] != gs.cell[q]) ++j;
      if (j == count) {
        cell[j] = gs.cell[q];
        for (int k = 0; k < K; ++k) acc[j][k] = 0;
        ++count;
      }
      for (int k = 0; k < K; ++k) acc[j][k] += gs.w[q] * v[k];
    }
    for (int i = 0; i < count_; ++i) {
      int j = 0;
      while (j < count && cell[j] != cell_[i]) ++j;
      if (j == count) {
        Emit(flush, cell_[i], acc_[i]);
        continue;
      }
      for (int k = 0; k < K; ++k) acc[j][k] += acc_[i][k];
    }
    for (int j = 0; j < count; ++j) cell_[j] = cell[j];
    Store(gs, acc, count);
  }

  // Call once per ray after its last sample.
  template <class Flush>
  PERF_HD_INLINE void Finish(Flush& flush) {
    for (int i = 0; i < count_; ++i) Emit(flush, cell_[i], acc_[i]);
    count_ = 0;
    distinct_ = false;
  }

 private:
  template <class Flush>
  PERF_HD_INLINE static void Emit(Flush& flush, int64_t cell, const T (&acc)[K]) {
    if (cell >= 0) flush(cell, acc);
  }
  // Keeps `count` entries; with 8 distinct cells they are in corner order (entry q = corner q).
  PERF_HD_INLINE void Store(const GridSample<T>& gs, const T (&acc)[8][K], int count) {
    for (int j = 0; j < count; ++j)
      for (int k = 0; k < K; ++k) acc_[j][k] = acc[j][k];
    count_ = count;
    distinct_ = gs.distinct && count == 8;
    if (distinct_) {
      for (int q = 0; q < 8; ++q) cell_[q] = gs.cell[q];
      for (int a = 0; a < 3; ++a) lo_[a] = gs.lo[a];
    }
  }

  int64_t cell_[8];
  T acc_[8][K];
  int lo_[3] = {0, 0, 0};
  int count_ = 0;
  bool distinct_ = false;
};

// A ray's photo exposure (ray_types.h ExposureParam, ray_math.h ColourTransform): with
// r_c = g_c H_c + b_c - C_c and g_c = 1 + gamma_c, the volume's partials of r_c are g_c times
// those of H_c (Backward's), and d r_c / d gamma_c = H_c, d r_c / d b_c = 1. param < 0: the
// photo's exposure is not solved (g = 1, no exposure entries).
//
// scale: the robust loss's row scale (RobustRowScale; 1 without). Iteratively reweighted least
// squares: at the linearisation point the ray's colour rows (residuals and Jacobian rows) are
// multiplied by s = sqrt(rho'(|r|^2)), so J^T r becomes the robust cost's gradient and J^T J its
// Gauss-Newton matrix with the weights held. The opacity residual L is not scaled.
// With param < 0 and scale 1 every function below leaves the volume's values exactly as they were.
template <class T>
struct RayExposure {
  int64_t param = -1;  // the photo's gamma_r
  T gain[3] = {1, 1, 1};
  T h[3] = {0, 0, 0};  // H at the linearisation point
  T scale = 1;
};

template <class T>
PERF_HD_INLINE RayExposure<T> ExposureOfRay(int64_t exposure_start, int slot, const ColourTransform<T>& xf,
                                            const T* h, T scale = T(1)) {
  RayExposure<T> e;
  e.scale = scale;
  if (slot < 0) return e;
  e.param = ExposureParam(exposure_start, slot);
  for (int c = 0; c < 3; ++c) {
    e.gain[c] = xf.gain[c];
    e.h[c] = h[c];
  }
  return e;
}

// The Cauchy loss rho(q) = c^2 log(1 + q / c^2) of a ray's squared colour residual q = |r|^2
// (ResidualSettings::robust_scale c; c <= 0: least squares, rho(q) = q), its row scale
// sqrt(rho'(q)) = 1 / sqrt(1 + q / c^2), and its cost 0.5 rho(q).
template <class T>
PERF_HD_INLINE T RobustRowScale(const T* residual, T c) {
  if (c <= 0) return T(1);
  const T q = residual[0] * residual[0] + residual[1] * residual[1] + residual[2] * residual[2];
  return T(1) / Sqrt(T(1) + q / (c * c));
}

// The residuals of the weighted system: the colour ones times the row scale.
template <class T>
PERF_HD_INLINE void ScaledResidual(const RayExposure<T>& e, const T r[4], T out[4]) {
  for (int c = 0; c < 3; ++c) out[c] = e.scale * r[c];
  out[3] = r[3];
}

// The residual vector the volume's partials multiply: (s g_c u_c, u_L).
template <class T>
PERF_HD_INLINE void VolumeU(const RayExposure<T>& e, const T u[4], T out[4]) {
  for (int c = 0; c < 3; ++c) out[c] = e.scale * e.gain[c] * u[c];
  out[3] = u[3];
}

// u = J_ray p from the volume's gathers `u` (of H; AddJpSample, AddJpShell): the colour entries
// become s (g_c u_c + H_c p[gamma_c] + p[b_c]).
template <class T>
PERF_HD_INLINE void FinishJp(const RayExposure<T>& e, const T* p, T u[4]) {
  for (int c = 0; c < 3; ++c) {
    const T exposure = e.param < 0 ? T(0) : e.h[c] * p[e.param + c] + p[e.param + 4 + c];
    u[c] = e.scale * (e.gain[c] * u[c] + exposure);
  }
}

// The exposure's share of J^T u (u: the ray's scaled residuals, or J p): s H_c u_c to gamma_c,
// s u_c to b_c.
template <class T, class Sink>
PERF_HD_INLINE void ScatterJtuExposure(const RayExposure<T>& e, const T u[4], Sink& sink) {
  if (e.param < 0) return;
  const T s = e.scale;
  sink.Add4(e.param, s * e.h[0] * u[0], s * e.h[1] * u[1], s * e.h[2] * u[2], T(0));
  sink.Add4(e.param + 4, s * u[0], s * u[1], s * u[2], T(0));
}

// The exposure's share of diag(J^T J): (s H_c)^2 and s^2 (one row entry each per ray).
template <class T, class Sink>
PERF_HD_INLINE void AddDiagExposure(const RayExposure<T>& e, Sink& sink) {
  if (e.param < 0) return;
  const T s2 = e.scale * e.scale;
  sink.Add4(e.param, s2 * e.h[0] * e.h[0], s2 * e.h[1] * e.h[1], s2 * e.h[2] * e.h[2], T(0));
  sink.Add4(e.param + 4, s2, s2, s2, T(0));
}

// The squared factors (s g_c)^2 that scale the volume's diagonal entries of colour residual c.
template <class T>
PERF_HD_INLINE void GainSquared(const RayExposure<T>& e, T g2[3]) {
  for (int c = 0; c < 3; ++c) g2[c] = e.scale * e.scale * e.gain[c] * e.gain[c];
}

// The row values whose merged sums give, squared, a cell's diag(J^T J) share: the colour entry
// dc (the same for the three colour residuals) and sigma's entries for the 4 residuals.
template <class T>
PERF_HD_INLINE void RowValues(const SamplePartials<T>& sp, T* v) {
  v[0] = sp.dc;
  v[1] = sp.ds[0];
  v[2] = sp.ds[1];
  v[3] = sp.ds[2];
  v[4] = sp.dl;
}
// diag entries of a cell from its merged row values (RowValues order); g2: the squared gains of
// the ray's photo (GainSquared; 1 without exposure): colour residual c's row entries are g_c times
// H_c's, and g_c is the same for every sample of the ray, so it factors out of the merged sums.
template <class T, class Sink>
PERF_HD_INLINE void AddDiagFromRow(int64_t cell, const T* row, const T* g2, Sink& sink) {
  const T c = row[0] * row[0];
  sink.Add4(GridParam(cell, 0), g2[0] * c, g2[1] * c, g2[2] * c,
            g2[0] * row[1] * row[1] + g2[1] * row[2] * row[2] + g2[2] * row[3] * row[3] + row[4] * row[4]);
}

// A shell's texels are reached by one lookup per ray: only repeats at the face border merge.
template <class T, class Sink>
PERF_HD_INLINE void AddDiagShell(const TexelSample<T>& ts, const ShellPartials<T>& sp, const T* g2, Sink& sink) {
  for (int q = 0; q < 4; ++q) {
    bool seen = false;
    for (int j = 0; j < q; ++j) seen = seen || ts.param[j] == ts.param[q];
    if (seen) continue;
    T w = 0;
    for (int j = q; j < 4; ++j) w += ts.param[j] == ts.param[q] ? ts.w[j] : T(0);
    const T c = w * sp.de;
    const T a = sp.opaque ? T(0)
                          : w * w * (g2[0] * sp.da[0] * sp.da[0] + g2[1] * sp.da[1] * sp.da[1] +
                                     g2[2] * sp.da[2] * sp.da[2]);
    sink.Add4(ts.param[q], g2[0] * c * c, g2[1] * c * c, g2[2] * c * c, a);
  }
}

}  // namespace perf::recon
