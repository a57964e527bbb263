#include "recon_cuda/solve/pose_blocks.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>

#include "common/errors.h"
#include "recon_cuda/core/pose.h"

namespace perf::recon {

void SolvePoseBlocks(int photos, std::span<const double> blocks, const float* r, const float* diag, const float* free,
                     float floor, float* z) {
  PERF_CHECK(static_cast<int64_t>(blocks.size()) == static_cast<int64_t>(photos) * kPoseBlock);
  for (int k = 0; k < photos; ++k) {
    const int64_t base = static_cast<int64_t>(kPoseValues) * k;
    Eigen::Matrix<double, kPoseSolved, kPoseSolved> b;
    Eigen::Matrix<double, kPoseSolved, 1> rhs;
    for (int a = 0; a < kPoseSolved; ++a) {
      const int64_t ia = base + a;
      const bool fa = free[ia] != 0.f;
      for (int c = 0; c < kPoseSolved; ++c) {
        const bool fc = free[base + c] != 0.f;
        const double jtj = blocks[kPoseBlock * k + PoseBlockEntry(std::min(a, c), std::max(a, c))];
        b(a, c) = a == c ? std::max(diag[ia], floor) : (fa && fc ? jtj : 0.0);
      }
      rhs(a) = fa ? r[ia] : 0.0;
    }
    const Eigen::LDLT<Eigen::Matrix<double, kPoseSolved, kPoseSolved>> ldlt(b);
    const bool ok = ldlt.info() == Eigen::Success && ldlt.isPositive() && (ldlt.vectorD().array() > 0).all();
    const Eigen::Matrix<double, kPoseSolved, 1> x = ok ? Eigen::Matrix<double, kPoseSolved, 1>(ldlt.solve(rhs))
                                                       : Eigen::Matrix<double, kPoseSolved, 1>(
                                                             rhs.array() / b.diagonal().array());
    for (int a = 0; a < kPoseSolved; ++a) {
      const int64_t ia = base + a;
      z[ia] = free[ia] != 0.f ? static_cast<float>(x(a)) : 0.f;
    }
  }
}

}  // namespace perf::recon
