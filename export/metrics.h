// Image metrics for `perf eval`: PSNR and SSIM (OpenCV's quality module, Wang et al. 2004:
// 11 x 11 Gaussian window, sigma 1.5, on the 8-bit value range), over the whole image or only
// inside a foreground mask (the paper's metric for real scenes: "masked out the foreground ...
// computed while applying these masks"), and the agreement of a mask with a true one.
#pragma once

#include <cstdint>

#include "workspace/image.h"

namespace perf::exporter {

struct ImageScores {
  double psnr = 0, ssim = 0;
  double psnr_masked = 0, ssim_masked = 0;  // over pixels where the mask is 1 (0 when none)
  double mask_coverage = 0;                 // fraction of pixels in the mask
};

// `render` and `photo`: RGB in [0, 1], same size. `mask`: one channel, binary; may be empty
// (then the masked scores are not computed).
ImageScores ScoreImage(const Image& render, const Image& photo, const Image& mask);

struct MaskAgreement {
  double iou = 0, precision = 0, recall = 0;
  int64_t ours = 0, truth = 0, both = 0;  // pixel counts
};

// Both binary, one channel, same size. IoU 1 when both are empty.
MaskAgreement CompareMasks(const Image& ours, const Image& truth);
// Adds the counts of `m` to `total` and recomputes its ratios (pooled over many images).
void Accumulate(MaskAgreement* total, const MaskAgreement& m);

}  // namespace perf::exporter
