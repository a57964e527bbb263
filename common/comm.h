// The processes of one reconstruction (docs/scaling.md): rank and size, sums over all
// ranks, a barrier, and ending the whole job. The solver and the backends never see which
// transport runs underneath: one process (SingleProcess, the default), MPI between processes
// (mpi_comm.h, with PERF_WITH_MPI), or NCCL between GPUs (its device sums, bootstrapped over MPI).
//
// Every sum is in a fixed order for a given number of ranks, and every rank receives the same
// bits, so that all ranks take the same step from the same parameters.
#pragma once

#include <cstddef>
#include <memory>
#include <span>
#include <string>

namespace perf {

class Communicator {
 public:
  virtual ~Communicator() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  // "1 process", "MPI, 4 ranks", "MPI + NCCL, 4 ranks".
  virtual std::string Describe() const = 0;

  // In place: every rank's values become the element-wise sum over the ranks.
  virtual void SumInPlace(std::span<float> values) = 0;
  virtual void SumInPlace(std::span<double> values) = 0;
  // In place: the element-wise maximum over the ranks.
  virtual void MaxInPlace(std::span<double> values) = 0;
  // The sum of `n` floats in device memory, where the transport reads device memory (NCCL);
  // false: it does not, and the caller sums a host copy with SumInPlace.
  virtual bool SumDeviceInPlace(float* /*device_values*/, size_t /*n*/) { return false; }
  virtual void Barrier() = 0;
  // Ends every rank of the job with exit code `code` (after the caller printed why). Returns only
  // for a single process, where it does nothing.
  virtual void Abort(int code) = 0;

  bool IsRoot() const { return rank() == 0; }
  // Whether any rank passed true (e.g. a stop request seen by one rank only).
  bool Any(bool mine);
  // Whether every rank passed the same value.
  bool Agree(double mine);
  // The first element's global index of rank r's share when rank r holds `mine` elements of a
  // sequence split in rank order (the exclusive prefix sum), and the total.
  struct Share {
    long long first = 0, total = 0;
  };
  Share ShareOf(long long mine);
};

// One process: every reduction is the identity.
class SingleProcess final : public Communicator {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  std::string Describe() const override { return "1 process"; }
  void SumInPlace(std::span<float>) override {}
  void SumInPlace(std::span<double>) override {}
  void MaxInPlace(std::span<double>) override {}
  void Barrier() override {}
  void Abort(int) override {}
};

// The job's communicator: MPI's world when this process was started by mpirun/srun in a build
// with MPI (initialised on first use, finalised at exit), else a SingleProcess. Never null.
Communicator& World();

// Whether this process was started by an MPI launcher (mpirun, mpiexec, srun): its environment
// says so. False in a plain shell.
bool LaunchedByMpi();

// This process's rank among the ranks on its node (the launcher's environment: Open MPI, Slurm,
// MPICH); 0 without a launcher.
int LocalRank();

// [begin, end) of rank `rank`'s share of `weights.size()` items split into `size` contiguous
// blocks of about equal total weight (e.g. the training photos by pixel count), every block
// non-empty when there are at least `size` items.
struct IndexRange {
  size_t begin = 0, end = 0;
  size_t size() const { return end - begin; }
};
IndexRange ContiguousShare(std::span<const double> weights, int rank, int size);

}  // namespace perf
