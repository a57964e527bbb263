// Ranks as threads of one process (distributed_backend.h tests): a Communicator over shared
// memory, so that data parallelism is tested without MPI, on the CPU and on one GPU.
#pragma once

#include <algorithm>
#include <barrier>
#include <cstdlib>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "common/comm.h"
#include "common/errors.h"

namespace perf::recon::test {

// `size` ranks that are threads: a sum copies every rank's values into a shared table and each
// rank adds the rows in rank order (a fixed order, as comm.h promises).
class ThreadGroup {
 public:
  explicit ThreadGroup(int size) : size_(size), sync_(size), rows_(static_cast<size_t>(size)) {}

  class Rank final : public Communicator {
   public:
    Rank(ThreadGroup* g, int rank) : g_(g), rank_(rank) {}
    int rank() const override { return rank_; }
    int size() const override { return g_->size_; }
    std::string Describe() const override { return StrCat(g_->size_, " threads"); }
    void SumInPlace(std::span<float> v) override { Reduce(v, [](double a, double b) { return a + b; }); }
    void SumInPlace(std::span<double> v) override { Reduce(v, [](double a, double b) { return a + b; }); }
    void MaxInPlace(std::span<double> v) override { Reduce(v, [](double a, double b) { return std::max(a, b); }); }
    void Barrier() override { g_->sync_.arrive_and_wait(); }
    void Abort(int) override { std::abort(); }

   private:
    template <class T, class Op>
    void Reduce(std::span<T> v, Op op) {
      g_->rows_[static_cast<size_t>(rank_)].assign(v.begin(), v.end());
      Barrier();
      for (size_t i = 0; i < v.size(); ++i) {
        T acc = static_cast<T>(g_->rows_[0][i]);
        for (int r = 1; r < g_->size_; ++r) acc = static_cast<T>(op(acc, static_cast<T>(g_->rows_[r][i])));
        v[i] = acc;
      }
      Barrier();  // nobody overwrites a row before every rank has read it
    }
    ThreadGroup* g_;
    int rank_;
  };

  // Runs body(rank communicator) on `size` threads and joins them.
  template <class Body>
  void Run(Body body) {
    std::vector<std::thread> threads;
    for (int r = 0; r < size_; ++r) {
      threads.emplace_back([this, r, &body] {
        Rank comm(this, r);
        body(comm);
      });
    }
    for (std::thread& t : threads) t.join();
  }

 private:
  int size_;
  std::barrier<> sync_;
  std::vector<std::vector<double>> rows_;
};

}  // namespace perf::recon::test
