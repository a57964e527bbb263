// Progress displays shared by the commands: one bar per step of a multi-step stage, and the
// reconstruction's iteration line.
#pragma once

#include <memory>
#include <string>

#include "pipeline/progress.h"
#include "recon_cuda/run/reconstruct.h"

namespace perf {

// One progress line per step ("export masks", "export mesh", ...), each finished when the next
// step starts.
class StepProgress {
 public:
  StepProgress(std::string label, bool quiet) : label_(std::move(label)), quiet_(quiet) {}
  void Update(const std::string& step, int done, int total);
  void Finish();

 private:
  std::string label_, step_;
  bool quiet_;
  std::unique_ptr<Progress> bar_;
};

// A reconstruction event on `progress`: its message, or the level, iteration, cost and
// training PSNR.
void ShowReconstructEvent(Progress& progress, const recon::ReconstructOptions::Event& e);

}  // namespace perf
