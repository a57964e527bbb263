#include "recon_cuda/backends/cpu_vectors.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "recon_cuda/core/param_ops.h"

namespace perf::recon {

template <class Fn, class Combine>
double CpuVectors::ReduceChunks(Fn&& fn, Combine&& combine) const {
  const int64_t n = size();
  std::vector<double> part((n + kChunk - 1) / kChunk, 0.0);
  arena_.execute([&] {
    tbb::parallel_for(int64_t{0}, static_cast<int64_t>(part.size()),
                      [&](int64_t c) { part[c] = fn(c * kChunk, std::min(n, (c + 1) * kChunk)); });
  });
  double r = 0;
  for (double p : part) r = combine(r, p);
  return r;
}

void CpuVectors::Assign(int count, int64_t n) {
  vectors_.clear();
  vectors_.assign(count, std::vector<float>(static_cast<size_t>(n), 0.f));
}

std::vector<float>& CpuVectors::operator[](VecId v) {
  PERF_CHECK(v >= 0 && v < static_cast<int>(vectors_.size()));
  return vectors_[v];
}

const std::vector<float>& CpuVectors::operator[](VecId v) const {
  PERF_CHECK(v >= 0 && v < static_cast<int>(vectors_.size()));
  return vectors_[v];
}

void CpuVectors::Upload(VecId v, std::span<const float> host) {
  std::vector<float>& a = (*this)[v];
  PERF_CHECK(host.size() == a.size());
  std::copy(host.begin(), host.end(), a.begin());
}

void CpuVectors::Download(VecId v, std::span<float> host) const {
  const std::vector<float>& a = (*this)[v];
  PERF_CHECK(host.size() == a.size());
  std::copy(a.begin(), a.end(), host.begin());
}

void CpuVectors::Fill(VecId v, float value) {
  float* a = (*this)[v].data();
  ForChunks([&](int64_t b, int64_t e) { std::fill(a + b, a + e, value); });
}

void CpuVectors::Copy(VecId dst, VecId src) {
  float* d = (*this)[dst].data();
  const float* s = (*this)[src].data();
  ForChunks([&](int64_t b, int64_t e) { std::copy(s + b, s + e, d + b); });
}

void CpuVectors::Axpy(VecId y, double a, VecId x) {
  float* py = (*this)[y].data();
  const float* px = (*this)[x].data();
  const float af = static_cast<float>(a);
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) py[i] += af * px[i];
  });
}

void CpuVectors::Xpby(VecId y, VecId x, double bb) {
  float* py = (*this)[y].data();
  const float* px = (*this)[x].data();
  const float bf = static_cast<float>(bb);
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) py[i] = px[i] + bf * py[i];
  });
}

void CpuVectors::DivideClamped(VecId z, VecId r, VecId d, float floor) {
  float* pz = (*this)[z].data();
  const float* pr = (*this)[r].data();
  const float* pd = (*this)[d].data();
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) pz[i] = pr[i] / std::max(pd[i], floor);
  });
}

void CpuVectors::AxpyDiag(VecId y, double a, VecId d, VecId x) {
  float* py = (*this)[y].data();
  const float* pd = (*this)[d].data();
  const float* px = (*this)[x].data();
  const float af = static_cast<float>(a);
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) py[i] += af * pd[i] * px[i];
  });
}

void CpuVectors::Multiply(VecId y, VecId m) {
  float* py = (*this)[y].data();
  const float* pm = (*this)[m].data();
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) py[i] *= pm[i];
  });
}

double CpuVectors::Dot(VecId a, VecId b) const {
  const float* pa = (*this)[a].data();
  const float* pb = (*this)[b].data();
  return ReduceChunks(
      [&](int64_t lo, int64_t hi) {
        double s = 0;
        for (int64_t i = lo; i < hi; ++i) s += static_cast<double>(pa[i]) * pb[i];
        return s;
      },
      [](double x, double y) { return x + y; });
}

double CpuVectors::MaxAbs(VecId v, int64_t count) const {
  const float* p = (*this)[v].data();
  const int64_t end = count < 0 ? size() : std::min(count, size());
  return ReduceChunks(
      [&](int64_t lo, int64_t hi) {
        float m = 0;
        for (int64_t i = lo; i < std::min(hi, end); ++i) m = std::max(m, std::abs(p[i]));
        return static_cast<double>(m);
      },
      [](double x, double y) { return std::max(x, y); });
}

void CpuVectors::Project(VecId x, const VolumeShape& shape) {
  float* p = (*this)[x].data();
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) p[i] = ProjectToValid(KindOf(shape, i), p[i]);
  });
}

void CpuVectors::HoldParameters(VecId x, VecId g, VecId free, const VolumeShape& shape, const HeldKinds& held_kinds,
                                bool bounds) {
  const float* px = (*this)[x].data();
  float* pg = (*this)[g].data();
  float* pf = (*this)[free].data();
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      const bool held = HeldParameter(KindOf(shape, i), px[i], pg[i], held_kinds, bounds);
      pf[i] = held ? 0.f : 1.f;
      if (held) pg[i] = 0.f;
    }
  });
}

void CpuVectors::AdamStep(VecId x, VecId g, VecId m, VecId v, const AdamSettings& s, int t, const VolumeShape& shape) {
  float* px = (*this)[x].data();
  const float* pg = (*this)[g].data();
  float* pm = (*this)[m].data();
  float* pv = (*this)[v].data();
  const AdamCoefficients a = AdamCoefficientsAt(s, t);
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) AdamUpdate(a, KindOf(shape, i), pg[i], &px[i], &pm[i], &pv[i]);
  });
  Project(x, shape);
}

void CpuVectors::AddSmoothness(VecId v, const VolumeShape& shape, const SmoothnessWeights& w, VecId out, VecId diag) {
  PERF_CHECK(out != v);
  const SmoothnessLayout layout = MakeSmoothnessLayout(shape);
  const float* pv = (*this)[v].data();
  float* po = out == kNoVector ? nullptr : (*this)[out].data();
  float* pd = diag == kNoVector ? nullptr : (*this)[diag].data();
  ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      float lap, degree;
      SmoothnessRow(layout, w, pv, i, &lap, &degree);
      if (po) po[i] += lap;
      if (pd) pd[i] += degree;
    }
  });
}

double CpuVectors::SmoothnessCost(VecId v, const VolumeShape& shape, const SmoothnessWeights& w) const {
  const SmoothnessLayout layout = MakeSmoothnessLayout(shape);
  const float* pv = (*this)[v].data();
  return ReduceChunks(
      [&](int64_t b, int64_t e) {
        double energy = 0;
        float lap, degree;
        for (int64_t i = b; i < e; ++i) energy += SmoothnessRow(layout, w, pv, i, &lap, &degree);
        return energy;
      },
      [](double x, double y) { return x + y; });
}

std::array<double, kParamKinds> CpuVectors::SumByKind(VecId v, const VolumeShape& shape) const {
  const float* pv = (*this)[v].data();
  std::array<double, kParamKinds> sums{};
  for (int kind = 0; kind < kParamKinds; ++kind) {
    sums[kind] = ReduceChunks(
        [&](int64_t b, int64_t e) {
          double s = 0;
          for (int64_t i = b; i < e; ++i) s += static_cast<int>(KindOf(shape, i)) == kind ? pv[i] : 0.f;
          return s;
        },
        [](double x, double y) { return x + y; });
  }
  return sums;
}

void SumParts(const CpuVectors& vectors, const std::vector<const float*>& parts, float* o) {
  vectors.ForChunks([&](int64_t b, int64_t e) {
    if (parts.empty()) {
      std::fill(o + b, o + e, 0.f);
      return;
    }
    std::copy(parts[0] + b, parts[0] + e, o + b);
    for (size_t k = 1; k < parts.size(); ++k) {
      const float* q = parts[k];
      for (int64_t i = b; i < e; ++i) o[i] += q[i];
    }
  });
}

void SumInterleavedParts(const CpuVectors& vectors, const std::vector<const float*>& parts, float* og, float* od) {
  vectors.ForChunks([&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      const int64_t at = 2 * (i - i % 4) + i % 4;
      og[i] = parts.empty() ? 0.f : parts[0][at];
      od[i] = parts.empty() ? 0.f : parts[0][at + 4];
      for (size_t k = 1; k < parts.size(); ++k) {
        og[i] += parts[k][at];
        od[i] += parts[k][at + 4];
      }
    }
  });
}

}  // namespace perf::recon
