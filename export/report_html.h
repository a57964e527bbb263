// The human-readable report of `perf eval`: one self-contained HTML file (no network, no
// external files): the summary numbers, a plot of the cameras around the box and a PSNR-vs-time
// plot of the solve from log.jsonl (inline SVG), and a strip of held-out renders next to their
// photos and masks (inline PNG thumbnails). Every figure is in report.json beside it, linked.
#pragma once

#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "export/metrics.h"
#include "workspace/image.h"
#include "workspace/scene.h"

namespace perf::exporter {

struct ReportStripView {
  std::string name;
  Image photo, render;  // RGB [0, 1]
  Image mask;           // our binary mask of the view, one channel [0, 1]; empty: none
  ImageScores scores;
};

// `report`: the content of report.json; `log_jsonl`: recon/log.jsonl's text (may be empty);
// `scene`: the cameras to plot (nullptr: no plot).
std::string ReportHtml(const nlohmann::json& report, const std::vector<ReportStripView>& strip,
                       const std::string& log_jsonl, const Scene* scene = nullptr);

// The cameras seen from above the plane of their centres (the box frame's two axes along which
// the centres spread most): the box, each camera's centre and viewing direction coloured by its
// split, and a refined camera's move (SVG text).
std::string CamerasPlotSvg(const Scene& scene);

// The PSNR-vs-time plot alone (SVG text): training PSNR per iteration and held-out PSNR where
// logged, against the solve's wall time. Empty when the log has no iterations.
std::string PsnrPlotSvg(const std::string& log_jsonl);

// Base64 (RFC 4648) of raw bytes, for data: URIs.
std::string Base64(const std::vector<unsigned char>& bytes);

}  // namespace perf::exporter
