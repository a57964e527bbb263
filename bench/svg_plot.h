// A minimal line plot written as SVG text (no plotting library on the GPU machine): PSNR against
// time for the benchmark's solvers, as in the paper's figure 1.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace perf::bench {

struct Series {
  std::string label, colour;                    // colour: any SVG colour ("#1f77b4")
  std::vector<std::pair<double, double>> xy;    // (x, y), in order
};

// Axes from 0 (x) and from the data's range (y), ticks at round values, a legend.
std::string LinePlotSvg(const std::vector<Series>& series, const std::string& title, const std::string& x_label,
                        const std::string& y_label);

}  // namespace perf::bench
