// Training photos the first level fits far worse than the others. A photo whose pose
// is a little off, or that shows what the others do not (a passer-by, motion blur), keeps a large
// error however the volume is fitted. perf reconstruct names such photos after the first level, in
// its output and in recon.json (`photo_fits`), and keeps training on them: on the bonsai example
// the photos that fit worst are the start of the capture, whose poses disagree with the rest by
// a shift of the object, and leaving them out lowered held-out PSNR (the held-out view among
// them lost its neighbours; docs/tuning.md "What limits the example").
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/comm.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/run/photo_corrections.h"
#include "recon_cuda/solve/backend.h"

namespace perf::recon {

struct PhotoFitOptions {
  // A photo fits poorly when its PSNR is more than this many dB below the median training photo's
  // (2.5 times the median's squared error). 4 sets the bonsai example's two worst-fitting photos
  // apart from the rest (docs/tuning.md "What limits the example").
  double max_db_below_median = 4.0;
};

struct PhotoFit {
  std::string name;
  double psnr = 0;
};

struct PhotoFits {
  double median_psnr = 0;
  std::vector<PhotoFit> poor;  // worst first
  // One line naming the poor fits, what they may mean and what to do; empty when there are none.
  std::string Warning(const PhotoFitOptions& options = {}) const;
  // recon.json's `photo_fits`: after_level (1), median_psnr, max_db_below_median, poor [{name, psnr}].
  nlohmann::json ToJson(const PhotoFitOptions& options = {}) const;
};

// The poor fits among photos `fits` (any order); none for fewer than 3 photos.
PhotoFits FindPoorFits(std::vector<PhotoFit> fits, const PhotoFitOptions& options = {});

// Every training photo rendered as shot at parameters x (evaluation.h RenderAsShot, its own
// exposure) and scored; the poor fits among them. share: this rank's training photos; names:
// every rank's, in scene.json order (collective over comm).
PhotoFits CheckPhotoFits(Backend* backend, VecId x, const std::vector<PosedImage>& share,
                         const std::vector<std::string>& names, const PhotoCorrections& exposures, Communicator& comm,
                         const PhotoFitOptions& options = {});

}  // namespace perf::recon
