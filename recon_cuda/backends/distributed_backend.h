// Data parallelism across ranks (docs/scaling.md): every rank holds the same parameters
// and its own share of the training rays (its photos); every pass is a sum over rays, so a pass
// runs on the rank's rays and its sums (cost, J^T r, diag(J^T J), J^T J p) are summed over the
// ranks. Everything else the solver does (vector operations, dot products, the smoothness term,
// renders) works on replicated vectors and needs no communication: the ranks compute the same
// bits and stay in step. The solver does not know it runs on several ranks.
//
// Ray subsets and jitter follow the rays' global index (RaySet::first_index), so N ranks fit the
// rays one process would, up to the order of float sums.
#pragma once

#include <memory>

#include "common/comm.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

class DistributedBackend final : public Backend {
 public:
  // comm must outlive this.
  DistributedBackend(std::unique_ptr<Backend> inner, Communicator* comm);

  // Bytes summed across ranks so far (each vector or scalar sum counted once, as sent by a rank).
  int64_t bytes_summed() const { return bytes_summed_; }
  // This rank's seconds so far in its own passes, and in the sums (which include waiting for the
  // slowest rank): their spread across ranks is the load imbalance.
  double pass_seconds() const { return pass_seconds_; }
  double sum_seconds() const { return sum_seconds_; }
  // Throws InternalError when the ranks' vectors v differ (they must never: a bug or a
  // non-deterministic reduction).
  void CheckInStep(VecId v) const;

  BackendKind kind() const override { return inner_->kind(); }
  std::string Describe() const override;
  // What the largest rank needs against what the smallest has: all ranks decide alike whether a
  // level fits (collective).
  MemoryEstimate EstimateMemory(const LevelProblem& problem, int num_vectors) const override;
  MemoryEstimate SetLevel(const LevelProblem& problem, int num_vectors) override;
  const LevelProblem& level() const override { return inner_->level(); }
  bool CachesJacobian() const override { return inner_->CachesJacobian(); }
  void ReleaseJacobian(bool keep_room) override { inner_->ReleaseJacobian(keep_room); }

  void Upload(VecId v, std::span<const float> host) override { inner_->Upload(v, host); }
  void Download(VecId v, std::span<float> host) const override { inner_->Download(v, host); }
  void Fill(VecId v, float value) override { inner_->Fill(v, value); }
  void Copy(VecId dst, VecId src) override { inner_->Copy(dst, src); }
  void Axpy(VecId y, double a, VecId x) override { inner_->Axpy(y, a, x); }
  void Xpby(VecId y, VecId x, double b) override { inner_->Xpby(y, x, b); }
  void DivideClamped(VecId z, VecId r, VecId d, float floor) override { inner_->DivideClamped(z, r, d, floor); }
  void AxpyDiag(VecId y, double a, VecId d, VecId x) override { inner_->AxpyDiag(y, a, d, x); }
  double Dot(VecId a, VecId b) const override { return inner_->Dot(a, b); }
  double MaxAbs(VecId v) const override { return inner_->MaxAbs(v); }
  double MaxAbsVolume(VecId v) const override { return inner_->MaxAbsVolume(v); }
  void Project(VecId x) override { inner_->Project(x); }
  void HoldParameters(VecId x, VecId g, VecId free, bool bounds) override { inner_->HoldParameters(x, g, free, bounds); }
  void Multiply(VecId y, VecId m) override { inner_->Multiply(y, m); }
  // PreconditionPoses is not forwarded: each rank's pose blocks hold its own rays only, and the
  // ranks must precondition alike; the pose values keep the Jacobi step (backend.h).
  void RestrictJacobian(VecId free) override { inner_->RestrictJacobian(free); }
  void AddSmoothness(VecId v, const SmoothnessWeights& w, VecId out, VecId diag) override {
    inner_->AddSmoothness(v, w, out, diag);
  }
  double SmoothnessCost(VecId v, const SmoothnessWeights& w) const override { return inner_->SmoothnessCost(v, w); }
  std::array<double, kParamKinds> SumByKind(VecId v) const override { return inner_->SumByKind(v); }
  void SumAcrossRanks(VecId v, Communicator& comm) override { inner_->SumAcrossRanks(v, comm); }
  void AdamStep(VecId x, VecId g, VecId m, VecId v, const AdamSettings& s, int t) override {
    inner_->AdamStep(x, g, m, v, s, t);
  }

  PassStats Linearize(VecId x, uint32_t seed, VecId g, VecId diag, RaySubset subset = {},
                      RaySubset jtj = {}) override;
  PassStats MultiplyJtJ(VecId p, VecId out) override;
  PassStats Cost(VecId x, uint32_t seed, RaySubset subset) override;
  RenderOutput Render(VecId x, const PinholeCamera<float>& camera, int width, int height,
                      float min_box_opacity) override {
    return inner_->Render(x, camera, width, height, min_box_opacity);
  }

 private:
  // The global subset as this rank's local ray indices see it.
  RaySubset Local(RaySubset global) const;
  void Sum(VecId v);
  void Sum(PassStats* s);

  std::unique_ptr<Backend> inner_;
  Communicator* comm_;
  int64_t first_index_ = 0;  // the level's RaySet::first_index
  int64_t bytes_summed_ = 0;
  double pass_seconds_ = 0, sum_seconds_ = 0;
};

}  // namespace perf::recon
