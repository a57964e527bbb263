#include "bench/svg_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace perf::bench {
namespace {

// A round tick step giving about `count` ticks over `range`.
double TickStep(double range, int count) {
  const double raw = range / count, p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * p >= raw) return m * p;
  }
  return 10 * p;
}

std::string Num(double v) {
  char b[32];
  std::snprintf(b, sizeof(b), "%g", v);
  return b;
}

}  // namespace

std::string LinePlotSvg(const std::vector<Series>& series, const std::string& title, const std::string& x_label,
                        const std::string& y_label) {
  double x_max = 0, y_min = 1e30, y_max = -1e30;
  for (const Series& s : series) {
    for (auto [x, y] : s.xy) {
      x_max = std::max(x_max, x);
      y_min = std::min(y_min, y);
      y_max = std::max(y_max, y);
    }
  }
  if (y_min > y_max) y_min = 0, y_max = 1;
  if (x_max <= 0) x_max = 1;
  const double ys = TickStep(std::max(y_max - y_min, 1e-9), 6), xs = TickStep(x_max, 8);
  y_min = std::floor(y_min / ys) * ys;
  y_max = std::ceil(y_max / ys) * ys;
  x_max = std::ceil(x_max / xs) * xs;
  const double w = 720, h = 440, l = 70, r = 20, t = 40, b = 55;
  auto px = [&](double x) { return l + (w - l - r) * x / x_max; };
  auto py = [&](double y) { return h - b - (h - t - b) * (y - y_min) / std::max(y_max - y_min, 1e-9); };
  std::ostringstream o;
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << w << "\" height=\"" << h
    << "\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  o << "<text x=\"" << w / 2 << "\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">" << title << "</text>\n";
  for (double y = y_min; y <= y_max + 1e-9; y += ys) {
    o << "<line x1=\"" << l << "\" x2=\"" << w - r << "\" y1=\"" << py(y) << "\" y2=\"" << py(y)
      << "\" stroke=\"#ddd\"/><text x=\"" << l - 6 << "\" y=\"" << py(y) + 4 << "\" text-anchor=\"end\">" << Num(y)
      << "</text>\n";
  }
  for (double x = 0; x <= x_max + 1e-9; x += xs) {
    o << "<line x1=\"" << px(x) << "\" x2=\"" << px(x) << "\" y1=\"" << t << "\" y2=\"" << h - b
      << "\" stroke=\"#eee\"/><text x=\"" << px(x) << "\" y=\"" << h - b + 16 << "\" text-anchor=\"middle\">"
      << Num(x) << "</text>\n";
  }
  o << "<rect x=\"" << l << "\" y=\"" << t << "\" width=\"" << w - l - r << "\" height=\"" << h - t - b
    << "\" fill=\"none\" stroke=\"black\"/>\n";
  o << "<text x=\"" << (l + w - r) / 2 << "\" y=\"" << h - 15 << "\" text-anchor=\"middle\">" << x_label
    << "</text>\n<text transform=\"translate(18," << (t + h - b) / 2 << ") rotate(-90)\" text-anchor=\"middle\">"
    << y_label << "</text>\n";
  int row = 0;
  for (const Series& s : series) {
    o << "<polyline fill=\"none\" stroke=\"" << s.colour << "\" stroke-width=\"2\" points=\"";
    for (auto [x, y] : s.xy) o << px(x) << "," << py(y) << " ";
    o << "\"/>\n";
    const double ly = t + 18 + 18 * row++;
    o << "<line x1=\"" << w - r - 150 << "\" x2=\"" << w - r - 125 << "\" y1=\"" << ly - 4 << "\" y2=\"" << ly - 4
      << "\" stroke=\"" << s.colour << "\" stroke-width=\"3\"/><text x=\"" << w - r - 118 << "\" y=\"" << ly << "\">"
      << s.label << "</text>\n";
  }
  o << "</svg>\n";
  return o.str();
}

}  // namespace perf::bench
