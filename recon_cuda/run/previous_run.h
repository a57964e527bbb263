// A fresh `perf reconstruct` must not destroy the last good result before it has one of its own
// (DESIGN.md "Safety"): the previous run's checkpoints, recon.json and log move to recon/previous/
// and come back if the new run fails before its first level is written; once it is written they
// are deleted. A run killed in between is repaired by the next reconstruct (RecoverPreviousRun).
#pragma once

#include <filesystem>

namespace perf::recon {

class PreviousRun {
 public:
  // Moves the previous run's files in `workspace`/recon aside (nothing to move: a no-op).
  explicit PreviousRun(const std::filesystem::path& workspace);
  // Not discarded: puts the previous run's files back, over whatever this run wrote.
  ~PreviousRun();
  PreviousRun(const PreviousRun&) = delete;
  PreviousRun& operator=(const PreviousRun&) = delete;

  // This run has written a level of its own: the previous run's files are deleted.
  void Discard();

 private:
  std::filesystem::path recon_, aside_;
  bool active_ = false;
};

// Call before reading any checkpoint: a recon/previous/ left by a killed run is put back when
// recon/ has no checkpoint of its own, and deleted otherwise.
void RecoverPreviousRun(const std::filesystem::path& workspace);

}  // namespace perf::recon
