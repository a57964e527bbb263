#include "export/report_html.h"

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <sstream>

namespace perf::exporter {

namespace {

// Thumbnails are at most this many pixels high.
constexpr int kThumbHeight = 200;

std::string Escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Fixed(double v, int digits) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(digits);
  s << v;
  return s.str();
}

// An RGB (or one-channel) [0, 1] image as a PNG data URI, scaled down to kThumbHeight (OpenCV's
// imencode).
std::string ThumbnailUri(const Image& im) {
  const bool grey = im.channels == 1;
  const cv::Mat rgb(im.height, im.width, grey ? CV_32FC1 : CV_32FC3, const_cast<float*>(im.pixels.data()));
  cv::Mat bgr8;
  rgb.convertTo(bgr8, grey ? CV_8UC1 : CV_8UC3, 255.0);
  if (!grey) cv::cvtColor(bgr8, bgr8, cv::COLOR_RGB2BGR);
  if (bgr8.rows > kThumbHeight) {
    const int w = std::max(1, static_cast<int>(std::lround(bgr8.cols * double(kThumbHeight) / bgr8.rows)));
    cv::resize(bgr8, bgr8, cv::Size(w, kThumbHeight), 0, 0, cv::INTER_AREA);
  }
  std::vector<unsigned char> png;
  cv::imencode(".png", bgr8, png);
  return "data:image/png;base64," + Base64(png);
}

struct LogPoint {
  double t, psnr;
};

}  // namespace

std::string Base64(const std::vector<unsigned char>& bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const uint32_t b0 = bytes[i], b1 = i + 1 < bytes.size() ? bytes[i + 1] : 0, b2 = i + 2 < bytes.size() ? bytes[i + 2] : 0;
    const uint32_t v = (b0 << 16) | (b1 << 8) | b2;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[v & 63] : '=';
  }
  return out;
}

std::string PsnrPlotSvg(const std::string& log_jsonl) {
  std::vector<LogPoint> train, test;
  std::vector<double> level_starts;
  int last_level = -1;
  std::istringstream lines(log_jsonl);
  for (std::string line; std::getline(lines, line);) {
    const nlohmann::json j = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (!j.is_object() || j.value("event", "") != "iteration" || !j.contains("elapsed")) continue;
    const double t = j["elapsed"].get<double>();
    if (j.contains("train_psnr")) train.push_back({t, j["train_psnr"].get<double>()});
    // A level without held-out views logs test_psnr 0: no point.
    if (j.contains("test_psnr") && j["test_psnr"].get<double>() > 0) test.push_back({t, j["test_psnr"].get<double>()});
    const int level = j.value("level", 0);
    if (level != last_level && last_level >= 0) level_starts.push_back(t);
    last_level = level;
  }
  if (train.empty() && test.empty()) return {};
  double t_max = 0, p_min = 1e9, p_max = -1e9;
  for (const auto* series : {&train, &test}) {
    for (const LogPoint& p : *series) {
      t_max = std::max(t_max, p.t);
      p_min = std::min(p_min, p.psnr);
      p_max = std::max(p_max, p.psnr);
    }
  }
  p_min = std::floor(p_min / 2) * 2;
  p_max = std::ceil(p_max / 2) * 2 + (p_max == p_min ? 2 : 0);
  t_max = t_max > 0 ? t_max : 1;
  constexpr double W = 640, H = 320, L = 50, R = 15, T = 15, B = 40;
  const auto X = [&](double t) { return L + (W - L - R) * t / t_max; };
  const auto Y = [&](double p) { return H - B - (H - T - B) * (p - p_min) / (p_max - p_min); };
  std::ostringstream s;
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H << "\" font-family=\"sans-serif\" font-size=\"11\">\n";
  s << "<rect x=\"" << L << "\" y=\"" << T << "\" width=\"" << W - L - R << "\" height=\"" << H - T - B
    << "\" fill=\"none\" stroke=\"#888\"/>\n";
  for (double p = p_min; p <= p_max + 1e-9; p += 2) {
    s << "<line x1=\"" << L << "\" x2=\"" << W - R << "\" y1=\"" << Y(p) << "\" y2=\"" << Y(p) << "\" stroke=\"#eee\"/>"
      << "<text x=\"" << L - 5 << "\" y=\"" << Y(p) + 4 << "\" text-anchor=\"end\">" << p << "</text>\n";
  }
  for (int k = 0; k <= 5; ++k) {
    const double t = t_max * k / 5;
    s << "<text x=\"" << X(t) << "\" y=\"" << H - B + 15 << "\" text-anchor=\"middle\">" << Fixed(t, 1) << "</text>\n";
  }
  for (double t : level_starts) {
    s << "<line x1=\"" << X(t) << "\" x2=\"" << X(t) << "\" y1=\"" << T << "\" y2=\"" << H - B
      << "\" stroke=\"#bbb\" stroke-dasharray=\"4 3\"/>\n";
  }
  s << "<text x=\"" << (L + W - R) / 2 << "\" y=\"" << H - 5 << "\" text-anchor=\"middle\">solver wall time (s)</text>\n";
  s << "<text x=\"12\" y=\"" << (T + H - B) / 2 << "\" text-anchor=\"middle\" transform=\"rotate(-90 12 " << (T + H - B) / 2
    << ")\">PSNR (dB)</text>\n";
  if (!train.empty()) {
    s << "<polyline fill=\"none\" stroke=\"#4477aa\" stroke-width=\"1.5\" points=\"";
    for (const LogPoint& p : train) s << X(p.t) << "," << Y(p.psnr) << " ";
    s << "\"/>\n";
  }
  for (const LogPoint& p : test) {
    s << "<circle cx=\"" << X(p.t) << "\" cy=\"" << Y(p.psnr) << "\" r=\"3.5\" fill=\"#ee6677\"/>\n";
  }
  // A legend entry only for a series that is drawn.
  double legend_y = T + 14;
  if (!train.empty()) {
    s << "<text x=\"" << L + 8 << "\" y=\"" << legend_y << "\" fill=\"#4477aa\">training rays (subset)</text>\n";
    legend_y += 14;
  }
  if (!test.empty()) {
    s << "<text x=\"" << L + 8 << "\" y=\"" << legend_y << "\" fill=\"#ee6677\">held-out views</text>\n";
  }
  s << "</svg>\n";
  return s.str();
}

std::string CamerasPlotSvg(const Scene& scene) {
  // Centres (imported and refined) in the box frame; the plot's axes are the two box axes with
  // the largest spread of the centres, seen from the third.
  const Eigen::Matrix3d rt = scene.box.rotation.transpose();
  const auto local = [&](const Eigen::Vector3d& p) { return Eigen::Vector3d(rt * (p - scene.box.center)); };
  Eigen::Vector3d spread = Eigen::Vector3d::Zero(), mean = Eigen::Vector3d::Zero();
  for (const SceneImage& im : scene.images) mean += local(im.world_from_cam.col(3));
  mean /= std::max<size_t>(1, scene.images.size());
  for (const SceneImage& im : scene.images) spread += (local(im.world_from_cam.col(3)) - mean).cwiseAbs2();
  int up = 0;
  spread.minCoeff(&up);
  const int ax = (up + 1) % 3, ay = (up + 2) % 3;
  // The extent: the box and the training and held-out cameras (left-out ones may be far: clamped).
  double extent = 0.5 * std::max(scene.box.size[ax], scene.box.size[ay]);
  for (const SceneImage& im : scene.images) {
    if (im.split == Split::kExcluded) continue;
    const Eigen::Vector3d c = local(im.world_from_cam.col(3));
    extent = std::max({extent, std::abs(c[ax]), std::abs(c[ay])});
  }
  extent *= 1.15;
  const double size = 360, half = size / 2;
  const auto X = [&](double v) { return half + std::clamp(v / extent, -1.0, 1.0) * (half - 6); };
  const auto Y = [&](double v) { return half - std::clamp(v / extent, -1.0, 1.0) * (half - 6); };
  std::ostringstream s;
  s << "<svg id=\"cameras-plot\" xmlns=\"http://www.w3.org/2000/svg\" width=\"" << size << "\" height=\"" << size
    << "\" style=\"background:#f7f7f7\">\n";
  const double bx = scene.box.size[ax] / 2, by = scene.box.size[ay] / 2;
  s << "<rect x=\"" << Fixed(X(-bx), 1) << "\" y=\"" << Fixed(Y(by), 1) << "\" width=\"" << Fixed(X(bx) - X(-bx), 1)
    << "\" height=\"" << Fixed(Y(-by) - Y(by), 1) << "\" fill=\"none\" stroke=\"#4477aa\"/>\n";
  const double arrow = 0.08 * extent;
  for (const SceneImage& im : scene.images) {
    const char* colour = im.split == Split::kTrain ? "#888888" : im.split == Split::kTest ? "#ee7733" : "#cc3311";
    const char* split = SplitName(im.split);
    const Eigen::Vector3d c = local(im.world_from_cam.col(3));
    const Eigen::Vector3d d = rt * im.world_from_cam.col(2);  // the optical axis
    s << "<g class=\"cam " << split << "\"><title>" << Escape(im.name) << " (" << split << ")</title>"
      << "<line x1=\"" << Fixed(X(c[ax]), 1) << "\" y1=\"" << Fixed(Y(c[ay]), 1) << "\" x2=\""
      << Fixed(X(c[ax] + arrow * d[ax]), 1) << "\" y2=\"" << Fixed(Y(c[ay] + arrow * d[ay]), 1) << "\" stroke=\""
      << colour << "\"/><circle cx=\"" << Fixed(X(c[ax]), 1) << "\" cy=\"" << Fixed(Y(c[ay]), 1)
      << "\" r=\"3\" fill=\"" << colour << "\"/></g>\n";
    if (im.refined_world_from_cam) {
      const Eigen::Vector3d r = local(im.refined_world_from_cam->col(3));
      s << "<line class=\"refined\" x1=\"" << Fixed(X(c[ax]), 1) << "\" y1=\"" << Fixed(Y(c[ay]), 1) << "\" x2=\""
        << Fixed(X(r[ax]), 1) << "\" y2=\"" << Fixed(Y(r[ay]), 1) << "\" stroke=\"#228833\" stroke-width=\"2\"/>\n";
    }
  }
  s << "<text x=\"6\" y=\"14\" font-size=\"11\" fill=\"#444\">box blue; training grey, held-out orange,</text>\n"
       "<text x=\"6\" y=\"27\" font-size=\"11\" fill=\"#444\">left out red; refined moves green</text>\n</svg>\n";
  return s.str();
}

std::string ReportHtml(const nlohmann::json& report, const std::vector<ReportStripView>& strip,
                       const std::string& log_jsonl, const Scene* scene) {
  std::ostringstream h;
  h << "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>PERF report</title>\n"
    << "<style>body{font-family:sans-serif;margin:2em;max-width:1100px}table{border-collapse:collapse}"
    << "td,th{padding:3px 10px;border-bottom:1px solid #ddd;text-align:right}th:first-child,td:first-child{text-align:left}"
    << ".strip{display:flex;flex-wrap:wrap;gap:14px}.strip figure{margin:0}.strip img{display:inline-block}"
    << "figcaption{font-size:12px;color:#444}</style></head><body>\n<h1>PERF reconstruction report</h1>\n";
  const nlohmann::json& mean = report["mean"];
  h << "<h2>Held-out views</h2>\n<table><tr><th></th><th>PSNR (dB)</th><th>SSIM</th><th>PSNR in mask</th><th>SSIM in mask</th><th>mask coverage</th></tr>\n";
  // masked: whether the row has a mask to score inside (a view's own mask, or any view's for the mean).
  const auto row = [&](const std::string& name, const nlohmann::json& s, bool masked) {
    h << "<tr><td>" << Escape(name) << "</td><td>" << Fixed(s["psnr"].get<double>(), 2) << "</td><td>"
      << Fixed(s["ssim"].get<double>(), 4) << "</td>";
    if (masked) {
      h << "<td>" << Fixed(s["psnr_masked"].get<double>(), 2) << "</td><td>" << Fixed(s["ssim_masked"].get<double>(), 4)
        << "</td>";
    } else {
      h << "<td>no mask</td><td>no mask</td>";
    }
    h << "<td>" << Fixed(100 * s["mask_coverage"].get<double>(), 1) << " %</td></tr>\n";
  };
  bool any_mask = false;
  for (const nlohmann::json& v : report["test_views"]) any_mask = any_mask || v["mask_coverage"].get<double>() > 0;
  row("mean of " + std::to_string(report["test_views"].size()) + " views", mean, any_mask);
  std::string doubts;  // the views whose imported pose is in doubt (scene.json pose_doubt), marked *
  for (const nlohmann::json& v : report["test_views"]) {
    const bool doubt = v.contains("pose_doubt");
    row(v["name"].get<std::string>() + (doubt ? " *" : ""), v, v["mask_coverage"].get<double>() > 0);
    if (doubt) doubts += "<li>" + Escape(v["name"].get<std::string>() + ": " + v["pose_doubt"].get<std::string>()) + "</li>";
  }
  h << "</table>\n";
  if (!doubts.empty()) h << "<p>* Their imported poses are in doubt (perf import):</p><ul>" << doubts << "</ul>\n";
  if (report.contains("held_out_cameras")) {
    const nlohmann::json& cams = report["held_out_cameras"];
    h << "<p>Held-out cameras (the headline): " << Escape(cams["headline"].get<std::string>()) << ".";
    if (!cams["pose_fit"].is_null()) {
      h << " After a test-time fit of each camera alone: mean PSNR "
        << Fixed(cams["pose_fit"]["mean_psnr"].get<double>(), 2) << " dB ("
        << Escape(cams["pose_fit"]["protocol"].get<std::string>()) << ").";
    }
    h << "</p>\n";
  }
  if (report.contains("masks")) {
    const nlohmann::json& m = report["masks"];
    h << "<h2>Foreground masks against the true ones (" << Escape(m["truth"].get<std::string>()) << ", "
      << m["images"].get<int>() << " images)</h2>\n<table><tr><th></th><th>IoU</th><th>precision</th><th>recall</th></tr>\n"
      << "<tr><td>pooled over all pixels</td><td>" << Fixed(m["pooled"]["iou"].get<double>(), 4) << "</td><td>"
      << Fixed(m["pooled"]["precision"].get<double>(), 4) << "</td><td>" << Fixed(m["pooled"]["recall"].get<double>(), 4)
      << "</td></tr>\n<tr><td>mean per image</td><td>" << Fixed(m["mean_iou"].get<double>(), 4)
      << "</td><td></td><td></td></tr></table>\n";
  }
  if (scene != nullptr && !scene->images.empty()) {
    h << "<h2>Cameras</h2>\n" << CamerasPlotSvg(*scene);
  }
  const std::string plot = PsnrPlotSvg(log_jsonl);
  if (!plot.empty()) h << "<h2>PSNR during the solve</h2>\n" << plot;
  if (!strip.empty()) {
    h << "<h2>Held-out renders, photos and our masks</h2>\n<div class=\"strip\">\n";
    for (const ReportStripView& v : strip) {
      h << "<figure><img src=\"" << ThumbnailUri(v.render) << "\" alt=\"render\"><img src=\"" << ThumbnailUri(v.photo)
        << "\" alt=\"photo\">";
      if (!v.mask.pixels.empty()) h << "<img src=\"" << ThumbnailUri(v.mask) << "\" alt=\"mask\">";
      h << "<figcaption>" << Escape(v.name) << ": " << Fixed(v.scores.psnr, 2) << " dB, SSIM " << Fixed(v.scores.ssim, 3)
        << "</figcaption></figure>\n";
    }
    h << "</div>\n";
  }
  h << "<p>Every figure, per view and per setting: <a href=\"report.json\">report.json</a> beside this file; "
       "<code>perf view</code> shows the workspace in 3-D.</p>\n</body></html>\n";
  return h.str();
}

}  // namespace perf::exporter
