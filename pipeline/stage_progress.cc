#include "pipeline/stage_progress.h"

#include <iomanip>
#include <sstream>

namespace perf {

void StepProgress::Update(const std::string& step, int done, int total) {
  if (step != step_) {
    if (bar_) bar_->Finish();
    bar_ = std::make_unique<Progress>(label_ + " " + step, quiet_);
    step_ = step;
  }
  bar_->Update(done, total, step == "masks" || step == "views" ? "images" : (step == "renders" ? "frames" : "parts"));
}

void StepProgress::Finish() {
  if (bar_) bar_->Finish();
}

void ShowReconstructEvent(Progress& progress, const recon::ReconstructOptions::Event& e) {
  if (!e.message.empty()) {
    progress.Message(e.message);
    return;
  }
  std::ostringstream unit;
  unit << "iterations, level " << e.level + 1 << "/" << e.levels << ", cost " << std::setprecision(5) << e.cost;
  if (e.train_psnr > 0) unit << ", train PSNR " << std::setprecision(4) << e.train_psnr << " dB";
  progress.Update(e.iteration, e.iterations, unit.str());
}

}  // namespace perf
