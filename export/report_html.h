// The human-readable report of `perf eval`: one self-contained HTML file (no network, no
// external files): the summary numbers, a PSNR-vs-time plot of the solve from log.jsonl (inline
// SVG), and a strip of held-out renders next to their photos (inline PNG thumbnails).
#pragma once

#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "export/metrics.h"
#include "workspace/image.h"

namespace perf::exporter {

struct ReportStripView {
  std::string name;
  Image photo, render;  // RGB [0, 1]
  ImageScores scores;
};

// `report`: the content of report.json; `log_jsonl`: recon/log.jsonl's text (may be empty).
std::string ReportHtml(const nlohmann::json& report, const std::vector<ReportStripView>& strip,
                       const std::string& log_jsonl);

// The PSNR-vs-time plot alone (SVG text): training PSNR per iteration and held-out PSNR where
// logged, against the solve's wall time. Empty when the log has no iterations.
std::string PsnrPlotSvg(const std::string& log_jsonl);

// Base64 (RFC 4648) of raw bytes, for data: URIs.
std::string Base64(const std::vector<unsigned char>& bytes);

}  // namespace perf::exporter
