#include "recon_cuda/backends/distributed_backend.h"

#include <vector>

#include "common/errors.h"
#include "common/stopwatch.h"

namespace perf::recon {

DistributedBackend::DistributedBackend(std::unique_ptr<Backend> inner, Communicator* comm)
    : inner_(std::move(inner)), comm_(comm) {
  PERF_CHECK(inner_ != nullptr && comm_ != nullptr);
}

std::string DistributedBackend::Describe() const {
  return comm_->size() == 1 ? inner_->Describe() : StrCat(inner_->Describe(), " x ", comm_->Describe());
}

MemoryEstimate DistributedBackend::EstimateMemory(const LevelProblem& problem, int num_vectors) const {
  MemoryEstimate e = inner_->EstimateMemory(problem, num_vectors);
  if (comm_->size() == 1) return e;
  // available: the smallest, as the maximum of its negative (0, unknown, counts as no limit).
  double v[6] = {static_cast<double>(e.vectors), static_cast<double>(e.scratch), static_cast<double>(e.jacobian_cache),
                 static_cast<double>(e.rays), e.available > 0 ? -static_cast<double>(e.available) : -1e300,
                 static_cast<double>(e.jacobian_wanted)};
  comm_->MaxInPlace(v);
  e.vectors = static_cast<int64_t>(v[0]);
  e.scratch = static_cast<int64_t>(v[1]);
  e.jacobian_cache = static_cast<int64_t>(v[2]);
  e.rays = static_cast<int64_t>(v[3]);
  e.available = v[4] > -1e299 ? static_cast<int64_t>(-v[4]) : 0;
  e.jacobian_wanted = static_cast<int64_t>(v[5]);
  return e;
}

MemoryEstimate DistributedBackend::SetLevel(const LevelProblem& problem, int num_vectors) {
  first_index_ = problem.rays != nullptr ? problem.rays->first_index : 0;
  return inner_->SetLevel(problem, num_vectors);
}

RaySubset DistributedBackend::Local(RaySubset global) const {
  if (global.stride == 1) return global;
  const int64_t shifted = (global.offset - first_index_) % global.stride;
  return {global.stride, static_cast<int>(shifted < 0 ? shifted + global.stride : shifted)};
}

void DistributedBackend::Sum(VecId v) {
  if (comm_->size() == 1) return;
  const auto t0 = WallClock::now();
  inner_->SumAcrossRanks(v, *comm_);
  sum_seconds_ += SecondsSince(t0);
  bytes_summed_ += level().shape.ParamCount() * static_cast<int64_t>(sizeof(float));
}

void DistributedBackend::Sum(PassStats* s) {
  if (comm_->size() == 1) return;
  pass_seconds_ += s->seconds;
  double v[5] = {s->cost, s->colour_sse, static_cast<double>(s->rays), static_cast<double>(s->samples), s->subset_cost};
  const auto t0 = WallClock::now();
  comm_->SumInPlace(v);
  sum_seconds_ += SecondsSince(t0);
  bytes_summed_ += static_cast<int64_t>(sizeof(v));
  s->cost = v[0];
  s->colour_sse = v[1];
  s->rays = static_cast<int64_t>(v[2]);
  s->samples = static_cast<int64_t>(v[3]);
  s->subset_cost = v[4];
}

PassStats DistributedBackend::Linearize(VecId x, uint32_t seed, VecId g, VecId diag, RaySubset subset,
                                        RaySubset jtj) {
  PERF_CHECK(subset.Valid() && jtj.Valid());
  PassStats s = inner_->Linearize(x, seed, g, diag, Local(subset), Local(jtj));
  if (g != kNoVector) Sum(g);
  if (diag != kNoVector) Sum(diag);
  Sum(&s);
  return s;
}

PassStats DistributedBackend::MultiplyJtJ(VecId p, VecId out) {
  PassStats s = inner_->MultiplyJtJ(p, out);
  Sum(out);
  Sum(&s);
  return s;
}

PassStats DistributedBackend::Cost(VecId x, uint32_t seed, RaySubset subset) {
  PERF_CHECK(subset.Valid());
  PassStats s = inner_->Cost(x, seed, Local(subset));
  Sum(&s);
  return s;
}

void DistributedBackend::CheckInStep(VecId v) const {
  if (comm_->size() == 1) return;
  const double d = inner_->Dot(v, v);
  if (!comm_->Agree(d)) {
    throw InternalError(StrCat("rank ", comm_->rank(), ": the ranks' parameters differ (|x|^2 = ", d,
                               " here); every rank must run the same perf build on the same workspace"));
  }
}

}  // namespace perf::recon
