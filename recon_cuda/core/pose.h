// Camera refinement inside Gauss-Newton (DESIGN.md "One ray", issue "--refine-poses"): the pose
// correction of a training photo (ray_types.h PoseParam) applied to its rays, and the analytic
// derivatives of a ray's residuals with respect to its origin and direction through the whole
// march: the box entry and exit (the samples slide along the ray with them), every sample's
// trilinear spatial gradient and its spherical harmonics' direction, the last segment's length,
// and the shells' cube-map lookups. Host and device, templated on the scalar like ray_math.h.
#pragma once

#include "recon_cuda/core/ray_math.h"

namespace perf::recon {

// R = exp([w]x) (Rodrigues) and the left Jacobian of SO(3) at w: R(w + e) = exp([J_l(w) e]x) R(w)
// to first order in e, so a change e of the stored rotation vector turns the ray's direction d by
// the angle vector J_l(w) e.
template <class T>
PERF_HD_INLINE void RotationOfVector(Vec3<T> w, Mat3<T>* rotation, Mat3<T>* left_jacobian) {
  const T th2 = Dot(w, w);
  T a, b, c;  // R = I + a [w] + b [w]^2, J_l = I + b [w] + c [w]^2
  if (th2 < T(1e-8)) {
    a = 1 - th2 / 6;
    b = T(0.5) - th2 / 24;
    c = T(1) / 6 - th2 / 120;
  } else {
    const T th = Sqrt(th2);
    a = Sin(th) / th;
    b = (1 - Cos(th)) / th2;
    c = (th - Sin(th)) / (th2 * th);
  }
  const T k[9] = {0, -w.z, w.y, w.z, 0, -w.x, -w.y, w.x, 0};
  T k2[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) k2[3 * i + j] = k[3 * i] * k[j] + k[3 * i + 1] * k[3 + j] + k[3 * i + 2] * k[6 + j];
  for (int i = 0; i < 9; ++i) {
    const T eye = i % 4 == 0 ? T(1) : T(0);
    rotation->m[i] = eye + a * k[i] + b * k2[i];
    left_jacobian->m[i] = eye + b * k[i] + c * k2[i];
  }
}

template <class T>
PERF_HD_INLINE Vec3<T> Cross(Vec3<T> a, Vec3<T> b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

// The pose parameters of a ray's photo: where they are in params (-1: its pose is not refined).
template <class T>
PERF_HD_INLINE int64_t PoseParamOfSlot(const VolumeView<T>& vol, int slot) {
  return slot < 0 || vol.poses == 0 ? int64_t{-1} : PoseParam(vol.PoseStart(), slot);
}

// The imported camera's optical axis (its +z) in the box frame: the direction that the focal
// correction (PoseParam's value 3) scales the rest of a ray's direction against.
template <class T>
PERF_HD_INLINE Vec3<T> BoxForward(const PinholeCamera<T>& cam, const BoxFrame<T>& box) {
  const T* m = cam.world_from_cam;
  return MulMatTransposed(box.world_from_box, Vec3<T>{m[2], m[6], m[10]});
}

// Moves a ray of the photo whose pose values are at `param` (>= 0) to the corrected pose: the
// focal length scaled by exp(f) (the direction's part across `forward`, the imported optical axis
// in the box frame, divided by exp(f)), the direction then turned by exp([w]x), the origin moved
// by s c (ray_types.h PoseParam), in the box frame. f = 0 leaves the direction's bits as they are.
template <class T>
PERF_HD_INLINE void ApplyPose(const VolumeView<T>& vol, const T* pose, Vec3<T> forward, BoxRay<T>* ray) {
  Mat3<T> r, jl;
  RotationOfVector(Vec3<T>{pose[0], pose[1], pose[2]}, &r, &jl);
  Vec3<T> d = ray->dir;
  if (pose[3] != 0) {
    const T along = Dot(d, forward);
    d = Normalized(forward + (d * (1 / along) - forward) * Exp(-pose[3]));
  }
  ray->origin = ray->origin + Vec3<T>{pose[4], pose[5], pose[6]} * vol.PoseScale();
  ray->dir = MulMat(r, d);
  SetGridRay(vol.size, vol.n, ray);
}

// d t / d (origin, direction) of a slab crossing t = (P - go_a) / gd_a along axis a: -1 / d_a and
// -t / d_a (grid units: go = S (o + size / 2), gd = S d, so the scale S cancels).
template <class T>
struct MarchEndGradient {
  T d_min[6], d_max[6];  // of t_min and t_max: origin x, y, z, then direction x, y, z
};

template <class T>
PERF_HD_INLINE MarchEndGradient<T> MarchEnds(const BoxRay<T>& ray, int n) {
  MarchEndGradient<T> e;
  for (int i = 0; i < 6; ++i) e.d_min[i] = e.d_max[i] = 0;
  T t0 = 0, t1 = T(3.0e38);
  int a0 = -1, a1 = -1;
  for (int a = 0; a < 3; ++a) {
    const T d = ray.grid_dir[a];
    if (d == 0) continue;
    T ta = (0 - ray.grid_origin[a]) / d, tb = (T(n) - ray.grid_origin[a]) / d;
    if (ta > tb) {
      const T s = ta;
      ta = tb;
      tb = s;
    }
    if (ta > t0) {
      t0 = ta;
      a0 = a;
    }
    if (tb < t1) {
      t1 = tb;
      a1 = a;
    }
  }
  if (a0 >= 0) {
    e.d_min[a0] = -1 / ray.dir[a0];
    e.d_min[3 + a0] = -t0 / ray.dir[a0];
  }
  if (a1 >= 0) {
    e.d_max[a1] = -1 / ray.dir[a1];
    e.d_max[3 + a1] = -t1 / ray.dir[a1];
  }
  return e;
}

// d Y_k / d d of the bands of ShBasis (d a unit vector; the derivative of the polynomials).
template <class T>
PERF_HD_INLINE void ShBasisGradient(int degree, Vec3<T> d, T (*dy)[3]) {
  const T c1 = T(0.4886025119029199), k1 = T(1.0925484305920792), k2 = T(0.31539156525252005),
          k3 = T(0.5462742152960396);
  const T g[8][3] = {{0, -c1, 0},
                     {0, 0, c1},
                     {-c1, 0, 0},
                     {k1 * d.y, k1 * d.x, 0},
                     {0, -k1 * d.z, -k1 * d.y},
                     {-2 * k2 * d.x, -2 * k2 * d.y, 4 * k2 * d.z},
                     {-k1 * d.z, 0, -k1 * d.x},
                     {2 * k3 * d.x, -2 * k3 * d.y, 0}};
  const int bands = ShBands(degree);
  for (int k = 0; k < bands; ++k)
    for (int a = 0; a < 3; ++a) dy[k][a] = g[k][a];
}

// d (u, v) / d w of DirectionToCube at w (not necessarily unit) on its face.
template <class T>
PERF_HD_INLINE void CubeGradient(Vec3<T> w, int face, T du[3], T dv[3]) {
  // Per face: the major axis and its sign, the axes and signs of sc and tc (DirectionToCube).
  const int major[6] = {0, 0, 1, 1, 2, 2}, s_axis[6] = {2, 2, 0, 0, 0, 0}, t_axis[6] = {1, 1, 2, 2, 1, 1};
  const T m_sign[6] = {1, -1, 1, -1, 1, -1}, s_sign[6] = {-1, 1, 1, 1, 1, -1}, t_sign[6] = {-1, -1, 1, -1, -1, -1};
  const T ma = m_sign[face] * w[major[face]];
  const T sc = s_sign[face] * w[s_axis[face]], tc = t_sign[face] * w[t_axis[face]];
  for (int a = 0; a < 3; ++a) du[a] = dv[a] = 0;
  du[s_axis[face]] += T(0.5) * s_sign[face] / ma;
  du[major[face]] -= T(0.5) * sc / (ma * ma) * m_sign[face];
  dv[t_axis[face]] += T(0.5) * t_sign[face] / ma;
  dv[major[face]] -= T(0.5) * tc / (ma * ma) * m_sign[face];
}

// The derivatives of a ray's four residuals (the colour of H, then L; before the exposure's gain
// and the robust scale, which the backends apply as they do to the volume's partials) with respect
// to the box-frame ray origin o and direction d.
template <class T>
struct RayGeometryGradient {
  T d_origin[4][3];
  T d_dir[4][3];
};

// A Backward visitor (ray_math.h) that accumulates RayGeometryGradient. The sample count is
// taken as fixed (a change of the pose that adds or drops a sample is a jump the derivative does
// not see); everything else that moves with the ray is differentiated.
template <class T>
struct GeometryVisitor {
  const VolumeView<T>& vol;
  const BoxRay<T>& ray;
  Jitter jit;
  March<T> march;
  MarchEndGradient<T> ends;
  RaySh<T> sh;
  RayGeometryGradient<T> grad;

  PERF_HD_INLINE GeometryVisitor(const VolumeView<T>& v, const BoxRay<T>& r, const Jitter& j)
      : vol(v), ray(r), jit(j), march(MakeMarch(v, r)), ends(MarchEnds(r, v.n)), sh(ShOfRay(v, r)) {
    for (int row = 0; row < 4; ++row)
      for (int a = 0; a < 3; ++a) grad.d_origin[row][a] = grad.d_dir[row][a] = 0;
  }

  // Adds dr[row] times d(quantity)/d(theta) for theta = (o, d): `dq[6]`.
  PERF_HD_INLINE void Add(int row, T factor, const T dq[6]) {
    for (int a = 0; a < 3; ++a) {
      grad.d_origin[row][a] += factor * dq[a];
      grad.d_dir[row][a] += factor * dq[3 + a];
    }
  }

  PERF_HD_INLINE void Sample(int k, const MarchStep<T>& st, const GridSample<T>& gs, const SamplePartials<T>& sp) {
    // How the sample's t and segment length move with the ray (ray_march.h StepAt): every sample
    // slides with t_min; the last, cut at t_max, also stretches with it.
    const T start = march.t_min + T(k) * march.delta;
    const T rest = march.t_max - start;
    const bool last = rest < march.delta && rest > 0;
    T dt[6], dlen[6] = {};
    if (last) {
      const T u = jit.enabled ? Uniform01<T>(jit.seed, jit.ray, static_cast<uint32_t>(k)) : T(0.5);
      for (int i = 0; i < 6; ++i) {
        dt[i] = (1 - u) * ends.d_min[i] + u * ends.d_max[i];
        dlen[i] = ends.d_max[i] - ends.d_min[i];
      }
    } else {
      for (int i = 0; i < 6; ++i) dt[i] = ends.d_min[i];
    }
    // The sample's values and their gradient in grid units (clamped axes do not move).
    const Vec3<T> g = ray.GridPoint(st.t);
    T f[3], moves[3];
    for (int a = 0; a < 3; ++a) {
      int lo, hi;
      LinearCoord(g[a], vol.n, &lo, &hi, &f[a]);
      const T c = g[a] - T(0.5);
      moves[a] = c > 0 && c < T(vol.n - 1) ? T(1) : T(0);
    }
    T value[4] = {0, 0, 0, 0}, dv[4][3], dcol_dir[3][3];
    for (int ch = 0; ch < 4; ++ch)
      for (int a = 0; a < 3; ++a) dv[ch][a] = 0;
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) dcol_dir[c][a] = 0;
    T dy[kMaxShBands][3];
    if (sh.degree > 0) ShBasisGradient(sh.degree, ray.dir, dy);
    const int stride = ShStride(sh.degree);
    for (int q = 0; q < 8; ++q) {
      if (gs.cell[q] < 0) continue;
      const int bit[3] = {q & 1, (q >> 1) & 1, (q >> 2) & 1};
      T fac[3], dw[3];
      for (int a = 0; a < 3; ++a) fac[a] = bit[a] ? f[a] : 1 - f[a];
      for (int a = 0; a < 3; ++a) {
        dw[a] = (bit[a] ? T(1) : T(-1)) * moves[a] * fac[(a + 1) % 3] * fac[(a + 2) % 3];
      }
      T cv[4];
      const T* p = vol.params + GridParam(gs.cell[q], 0);
      for (int ch = 0; ch < 4; ++ch) cv[ch] = p[ch];
      if (sh.degree > 0) {
        const T* band = vol.params + sh.start + stride * gs.cell[q];
        for (int kb = 0; kb < sh.bands; ++kb) {
          for (int c = 0; c < 3; ++c) {
            cv[c] += sh.y[kb] * band[3 * kb + c];
            for (int a = 0; a < 3; ++a) dcol_dir[c][a] += gs.w[q] * dy[kb][a] * band[3 * kb + c];
          }
        }
      }
      for (int ch = 0; ch < 4; ++ch) {
        value[ch] += gs.w[q] * cv[ch];
        for (int a = 0; a < 3; ++a) dv[ch][a] += dw[a] * cv[ch];
      }
    }
    // d g_b / d o_a = S_b (delta_ab + d_b dt/do_a), d g_b / d d_a = S_b (t delta_ab + d_b dt/dd_a):
    // with G_b = dv_b S_b, d value / d o_a = G_a + (G . d) dt/do_a, and t G_a for d_a.
    const T s[3] = {T(vol.n) / vol.size.x, T(vol.n) / vol.size.y, T(vol.n) / vol.size.z};
    T dval[4][6];
    for (int ch = 0; ch < 4; ++ch) {
      const T g[3] = {dv[ch][0] * s[0], dv[ch][1] * s[1], dv[ch][2] * s[2]};
      const T along = g[0] * ray.dir[0] + g[1] * ray.dir[1] + g[2] * ray.dir[2];
      for (int a = 0; a < 3; ++a) {
        dval[ch][a] = g[a] + along * dt[a];
        dval[ch][3 + a] = st.t * g[a] + along * dt[3 + a];
      }
    }
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) dval[c][3 + a] += dcol_dir[c][a];
    // Residual rows: d r_c = dc dcolour_c + ds_c dsigma + (sigma / delta) ds_c dlen (sigma and the
    // segment length enter only through their product), d L likewise with dl.
    const T per_len = st.delta > 0 ? value[3] / st.delta : T(0);
    for (int c = 0; c < 3; ++c) {
      Add(c, sp.dc, dval[c]);
      Add(c, sp.ds[c], dval[3]);
      if (last) Add(c, per_len * sp.ds[c], dlen);
    }
    Add(3, sp.dl, dval[3]);
    if (last) Add(3, per_len * sp.dl, dlen);
  }

  PERF_HD_INLINE void Shell(int k, const CubeCoord<T>& coord, const TexelSample<T>& ts, const ShellPartials<T>& sp) {
    // The exit point p = o + t d on the sphere: w = p - c, t = -b + sqrt(disc), b = (o - c) . d.
    const Vec3<T> oc = ray.origin - vol.shell_center;
    const T b = Dot(oc, ray.dir);
    const T disc = b * b - (Dot(oc, oc) - vol.shell_radii[k] * vol.shell_radii[k]);
    if (!(disc > 0)) return;  // grazing: no derivative
    const T root = Sqrt(disc), t = -b + root;
    const Vec3<T> w = oc + ray.dir * t;
    T dt[6];
    for (int a = 0; a < 3; ++a) {
      dt[a] = -ray.dir[a] + (b * ray.dir[a] - oc[a]) / root;
      dt[3 + a] = oc[a] * (b / root - 1);
    }
    T du[3], dv[3];
    CubeGradient(w, coord.face, du, dv);
    // The texels' bilinear gradient in (u, v) (shells.h TexelWeights; clamped coordinates do not move).
    int lo, hi;
    T fu, fv;
    LinearCoord(coord.u * T(vol.m), vol.m, &lo, &hi, &fu);
    LinearCoord(coord.v * T(vol.m), vol.m, &lo, &hi, &fv);
    const T cu = coord.u * T(vol.m) - T(0.5), cv = coord.v * T(vol.m) - T(0.5);
    const T mu = cu > 0 && cu < T(vol.m - 1) ? T(vol.m) : T(0), mv = cv > 0 && cv < T(vol.m - 1) ? T(vol.m) : T(0);
    T dtex_u[4], dtex_v[4];
    for (int ch = 0; ch < 4; ++ch) {
      const T t0 = vol.params[ts.param[0] + ch], t1 = vol.params[ts.param[1] + ch];
      const T t2 = vol.params[ts.param[2] + ch], t3 = vol.params[ts.param[3] + ch];
      dtex_u[ch] = mu * ((1 - fv) * (t1 - t0) + fv * (t3 - t2));
      dtex_v[ch] = mv * ((1 - fu) * (t2 - t0) + fu * (t3 - t1));
    }
    // d w / d o_a = e_a + d dt/do_a, d w / d d_a = t e_a + d dt/dd_a.
    T duv[2][6];
    for (int i = 0; i < 6; ++i) {
      const int a = i % 3;
      T su = 0, sv = 0;
      for (int bb = 0; bb < 3; ++bb) {
        const T dw = (bb == a ? (i < 3 ? T(1) : t) : T(0)) + ray.dir[bb] * dt[i];
        su += du[bb] * dw;
        sv += dv[bb] * dw;
      }
      duv[0][i] = su;
      duv[1][i] = sv;
    }
    for (int c = 0; c < 3; ++c) {
      T dq[6];
      for (int i = 0; i < 6; ++i) {
        const T de = dtex_u[c] * duv[0][i] + dtex_v[c] * duv[1][i];
        const T da = sp.opaque ? T(0) : dtex_u[3] * duv[0][i] + dtex_v[3] * duv[1][i];
        dq[i] = sp.de * de + sp.da[c] * da;
      }
      Add(c, T(1), dq);
    }
  }
};

// The Jacobian of a ray's four residuals with respect to its photo's 8 pose values (PoseParam
// order; the padding column 7 is 0): rotation column a = (J_l(w)^T (d x grad_d r))_a, focal column
// = grad_d r . (d . F)(F - (d . F) d) with F = exp([w]x) forward (the corrected optical axis),
// centre column a = s grad_o r_a; d the corrected direction, w the stored rotation vector.
template <class T>
struct PoseRow {
  T j[4][kPoseValues];
};

template <class T>
PERF_HD_INLINE PoseRow<T> PoseRowOf(const VolumeView<T>& vol, const T* pose, Vec3<T> forward, const BoxRay<T>& ray,
                                    const RayGeometryGradient<T>& g) {
  Mat3<T> r, jl;
  RotationOfVector(Vec3<T>{pose[0], pose[1], pose[2]}, &r, &jl);
  const T s = vol.PoseScale();
  const Vec3<T> axis = MulMat(r, forward);
  const T along = Dot(ray.dir, axis);
  const Vec3<T> dfocal = (axis - ray.dir * along) * along;  // d direction / d f
  PoseRow<T> row;
  for (int k = 0; k < 4; ++k) {
    const Vec3<T> gd{g.d_dir[k][0], g.d_dir[k][1], g.d_dir[k][2]};
    const Vec3<T> rot = MulMatTransposed(jl, Cross(ray.dir, gd));
    for (int a = 0; a < 3; ++a) {
      row.j[k][a] = rot[a];
      row.j[k][4 + a] = s * g.d_origin[k][a];
    }
    row.j[k][3] = Dot(gd, dfocal);
    row.j[k][7] = 0;
  }
  return row;
}

// J_pose p for a ray: u[row] += sum_j row.j[row][j] p[param + j] (u in H's units, before FinishJp).
template <class T>
PERF_HD_INLINE void AddJpPose(const PoseRow<T>& row, const T* p, int64_t param, T u[4]) {
  for (int k = 0; k < 4; ++k) {
    T sum = 0;
    for (int j = 0; j < kPoseValues; ++j) sum += row.j[k][j] * p[param + j];
    u[k] += sum;
  }
}

// J_pose^T u into the sink (u: VolumeU's residuals, the colour rows already scaled by s g_c).
template <class T, class Sink>
PERF_HD_INLINE void ScatterJtuPose(const PoseRow<T>& row, int64_t param, const T u[4], Sink& sink) {
  T v[kPoseValues];
  for (int j = 0; j < kPoseValues; ++j) v[j] = row.j[0][j] * u[0] + row.j[1][j] * u[1] + row.j[2][j] * u[2] + row.j[3][j] * u[3];
  sink.Add4(param, v[0], v[1], v[2], v[3]);
  sink.Add4(param + 4, v[4], v[5], v[6], v[7]);
}

// The pose's share of diag(J^T J): sum over the rows of g2_row row.j^2 (g2: GainSquared, 1 for L).
template <class T, class Sink>
PERF_HD_INLINE void AddDiagPose(const PoseRow<T>& row, int64_t param, const T* g2, Sink& sink) {
  T v[kPoseValues];
  for (int j = 0; j < kPoseValues; ++j) {
    v[j] = g2[0] * row.j[0][j] * row.j[0][j] + g2[1] * row.j[1][j] * row.j[1][j] + g2[2] * row.j[2][j] * row.j[2][j] +
           row.j[3][j] * row.j[3][j];
  }
  sink.Add4(param, v[0], v[1], v[2], v[3]);
  sink.Add4(param + 4, v[4], v[5], v[6], v[7]);
}

// The pose block of J^T J (block-Jacobi preconditioning, solve/pose_blocks.h): per photo the
// products of its 7 solved values, the first 7 of PoseParam order (rotation, focal, centre; the
// padding last), the upper triangle row by row (28 values, a multiple of 4 for the CUDA group sums).
inline constexpr int kPoseSolved = 7;
inline constexpr int kPoseBlock = kPoseSolved * (kPoseSolved + 1) / 2;
// Where entry (a, b), a <= b, of the upper triangle is.
PERF_HD_INLINE int PoseBlockEntry(int a, int b) { return a * kPoseSolved - a * (a - 1) / 2 + (b - a); }

// block += the ray's share: sum over the rows of g2_row J[row][a] J[row][b] (g2 as AddDiagPose's).
template <class T, class Acc>
PERF_HD_INLINE void AddPoseBlock(const PoseRow<T>& row, const T* g2, Acc* block) {
  int e = 0;
  for (int a = 0; a < kPoseSolved; ++a) {
    for (int b = a; b < kPoseSolved; ++b, ++e) {
      T s = row.j[3][a] * row.j[3][b];
      for (int r = 0; r < 3; ++r) s += g2[r] * row.j[r][a] * row.j[r][b];
      block[e] += s;
    }
  }
}

// Calls a.X and b.X for each Backward callback: one sweep feeds two visitors.
template <class A, class B>
struct BothVisitors {
  A& a;
  B& b;
  template <class T>
  PERF_HD_INLINE void Shell(int k, const CubeCoord<T>& c, const TexelSample<T>& ts, const ShellPartials<T>& sp) {
    a.Shell(k, c, ts, sp);
    b.Shell(k, c, ts, sp);
  }
  template <class T>
  PERF_HD_INLINE void Sample(int k, const MarchStep<T>& st, const GridSample<T>& gs, const SamplePartials<T>& sp) {
    a.Sample(k, st, gs, sp);
    b.Sample(k, st, gs, sp);
  }
};

}  // namespace perf::recon
