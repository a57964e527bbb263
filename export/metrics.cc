#include "export/metrics.h"

#include <opencv2/core.hpp>
#include <opencv2/quality/qualityssim.hpp>

#include <cmath>

#include "common/errors.h"
#include "recon_cuda/run/evaluation.h"

namespace perf::exporter {

namespace {

// OpenCV's SSIM constants are those of 8-bit images (C1 = (0.01 * 255)^2), so values in
// [0, 1] are scaled to [0, 255].
cv::Mat To255(const Image& im) {
  const cv::Mat view(im.height, im.width, CV_32FC(im.channels), const_cast<float*>(im.pixels.data()));
  cv::Mat out;
  view.convertTo(out, CV_32F, 255.0);
  return out;
}

void RatiosFromCounts(MaskAgreement* m) {
  const int64_t uni = m->ours + m->truth - m->both;
  m->iou = uni == 0 ? 1.0 : static_cast<double>(m->both) / uni;
  m->precision = m->ours == 0 ? (m->truth == 0 ? 1.0 : 0.0) : static_cast<double>(m->both) / m->ours;
  m->recall = m->truth == 0 ? 1.0 : static_cast<double>(m->both) / m->truth;
}

}  // namespace

ImageScores ScoreImage(const Image& render, const Image& photo, const Image& mask) {
  PERF_CHECK(render.channels == 3 && photo.channels == 3 && render.width == photo.width &&
             render.height == photo.height);
  const bool masked = !mask.empty();
  PERF_CHECK(!masked || (mask.channels == 1 && mask.width == render.width && mask.height == render.height));
  const size_t pixels = static_cast<size_t>(render.width) * render.height;

  const cv::Mat a = To255(render), b = To255(photo);
  cv::Mat ssim_map;  // per pixel, one channel per colour channel
  const cv::Scalar ssim = cv::quality::QualitySSIM::compute(a, b, ssim_map);
  // The map comes back in OpenCV's internal working type (CV_64F on this OpenCV).
  ssim_map.convertTo(ssim_map, CV_32F);
  PERF_CHECK_MSG(ssim_map.channels() == 3 && ssim_map.rows == render.height && ssim_map.cols == render.width,
                 "unexpected SSIM map ", ssim_map.rows, "x", ssim_map.cols, "x", ssim_map.channels());
  ImageScores s;
  s.ssim = (ssim[0] + ssim[1] + ssim[2]) / 3;

  double sse = 0, sse_in = 0, ssim_in = 0;
  int64_t in = 0;
  for (size_t p = 0; p < pixels; ++p) {
    double e = 0;
    for (int c = 0; c < 3; ++c) {
      const double d = static_cast<double>(render.pixels[3 * p + c]) - photo.pixels[3 * p + c];
      e += d * d;
    }
    sse += e;
    if (masked && mask.pixels[p] >= 0.5f) {
      sse_in += e;
      const cv::Vec3f& q = ssim_map.at<cv::Vec3f>(static_cast<int>(p / render.width), static_cast<int>(p % render.width));
      ssim_in += (q[0] + q[1] + q[2]) / 3.0;
      ++in;
    }
  }
  s.psnr = recon::PsnrFromMse(sse / (3.0 * pixels));
  if (masked) {
    s.mask_coverage = static_cast<double>(in) / pixels;
    if (in > 0) {
      s.psnr_masked = recon::PsnrFromMse(sse_in / (3.0 * in));
      s.ssim_masked = ssim_in / in;
    }
  }
  return s;
}

MaskAgreement CompareMasks(const Image& ours, const Image& truth) {
  PERF_CHECK(ours.channels == 1 && truth.channels == 1 && ours.width == truth.width && ours.height == truth.height);
  MaskAgreement m;
  for (size_t p = 0; p < ours.pixels.size(); ++p) {
    const bool o = ours.pixels[p] >= 0.5f, t = truth.pixels[p] >= 0.5f;
    m.ours += o;
    m.truth += t;
    m.both += o && t;
  }
  RatiosFromCounts(&m);
  return m;
}

void Accumulate(MaskAgreement* total, const MaskAgreement& m) {
  total->ours += m.ours;
  total->truth += m.truth;
  total->both += m.both;
  RatiosFromCounts(total);
}

}  // namespace perf::exporter
