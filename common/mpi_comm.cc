#include "common/mpi_comm.h"

#include <mpi.h>

#include <algorithm>
#include <cstdlib>
#include <string>
#include <vector>

#include "common/errors.h"

namespace perf {
namespace {

void Check(int rc, const char* what) {
  if (rc != MPI_SUCCESS) {
    char text[MPI_MAX_ERROR_STRING];
    int len = 0;
    MPI_Error_string(rc, text, &len);
    throw Error(StrCat("MPI ", what, " failed: ", std::string(text, static_cast<size_t>(len))));
  }
}

class MpiCommunicator final : public Communicator {
 public:
  MpiCommunicator() {
    int initialised = 0;
    MPI_Initialized(&initialised);
    if (!initialised) {
      int provided = 0;
      Check(MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
      std::atexit([] {
        int finalised = 0;
        MPI_Finalized(&finalised);
        if (!finalised) MPI_Finalize();
      });
    }
    // Errors come back as codes (Check turns them into exceptions, main ends the job).
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }

  int rank() const override { return rank_; }
  int size() const override { return size_; }
  std::string Describe() const override { return StrCat("MPI, ", size_, size_ == 1 ? " rank" : " ranks"); }

  void SumInPlace(std::span<float> v) override { Reduce(v.data(), v.size(), MPI_FLOAT, MPI_SUM); }
  void SumInPlace(std::span<double> v) override { Reduce(v.data(), v.size(), MPI_DOUBLE, MPI_SUM); }
  void MaxInPlace(std::span<double> v) override { Reduce(v.data(), v.size(), MPI_DOUBLE, MPI_MAX); }
  void Barrier() override { Check(MPI_Barrier(MPI_COMM_WORLD), "MPI_Barrier"); }
  void Abort(int code) override { MPI_Abort(MPI_COMM_WORLD, code); }

 private:
  // In chunks that an int count can address.
  template <class T>
  void Reduce(T* data, size_t n, MPI_Datatype type, MPI_Op op) {
    if (size_ == 1 || n == 0) return;
    constexpr size_t kChunk = size_t{1} << 28;
    for (size_t at = 0; at < n; at += kChunk) {
      const int count = static_cast<int>(std::min(kChunk, n - at));
      void* send = rank_ == 0 ? MPI_IN_PLACE : static_cast<void*>(data + at);
      Check(MPI_Reduce(send, rank_ == 0 ? data + at : nullptr, count, type, op, 0, MPI_COMM_WORLD), "MPI_Reduce");
      Check(MPI_Bcast(data + at, count, type, 0, MPI_COMM_WORLD), "MPI_Bcast");
    }
  }

  int rank_ = 0, size_ = 1;
};

}  // namespace

Communicator& MpiWorld() {
  static MpiCommunicator world;
  return world;
}

}  // namespace perf
