// The presets of `perf run` (PresetFor), their line for the terminal, the default time budget
// per preset and device, and durations as users write them (run_pipeline.h).
#include <cmath>
#include <sstream>
#include <string>

#include "common/errors.h"
#include "pipeline/run_pipeline.h"
#include "recon_cuda/run/level_choice.h"

namespace perf {

namespace {

constexpr const char* kCommandLine = "command line";

// Where the bands are solved, in words (recon::ShFromLevelIndex says how the value counts);
// levels 0: from the photos.
std::string ShLevels(int sh_from_level, int levels) {
  if (sh_from_level == 0) return "at the last level";
  if (sh_from_level < 0) return StrCat("at the last ", 1 - sh_from_level, " levels");
  return StrCat("from level ", sh_from_level, levels == 0 ? " (or the last, if there are fewer)" : "");
}
}  // namespace

std::string PresetSettings::Describe() const {
  using recon::BackendKind;
  const std::string finest =
      max_resolution > 0 ? StrCat("at most ", max_resolution, "^3")
                         : StrCat("at most ", recon::DefaultMaxResolution(BackendKind::kCpu), "^3 on a CPU, ",
                                  recon::DefaultMaxResolution(BackendKind::kCuda), "^3 on a GPU");
  std::ostringstream s;
  s << "images " << (max_size > 0 ? "at most " + std::to_string(max_size) + " px" : std::string("full size")) << ", "
    << (levels > 0 ? std::to_string(levels) + " levels" : "levels from the photos (finest grid " + finest + ")")
    << " x at most " << iterations
    << " Gauss-Newton iterations, "
    << (sh_degree > 0 ? StrCat("view-dependent colour (degree ", sh_degree, ") ", ShLevels(sh_from_level, levels), ", ") : "")
    << orbit_frames << " orbit frames";
  return s.str();
}

double DefaultTimeBudget(const std::string& preset, bool gpu) {
  if (preset == "preview") return gpu ? 120 : 600;
  if (preset == "high") return gpu ? 3600 : 14400;
  return gpu ? 900 : 3600;
}

double ParseDuration(const std::string& text, const std::string& option) {
  const auto bad = [&](const std::string& why) {
    return InputError(kCommandLine, option, text, why, "write e.g. 90s, 10m, 1.5h or 1h30m (none: no budget)");
  };
  if (text == "none") return 0;
  double total = 0;
  size_t at = 0;
  while (at < text.size()) {
    size_t used = 0;
    double v = 0;
    try {
      v = std::stod(text.substr(at), &used);
    } catch (const std::exception&) {
      throw bad("not a duration");
    }
    if (!std::isfinite(v) || v < 0) throw bad("must be a finite duration of at least 0");
    at += used;
    const char unit = at < text.size() ? text[at] : 's';
    if (at < text.size()) ++at;
    if (unit == 'h') {
      v *= 3600;
    } else if (unit == 'm') {
      v *= 60;
    } else if (unit != 's') {
      throw bad(StrCat("unknown unit '", unit, "'"));
    }
    total += v;
  }
  if (text.empty()) throw bad("empty");
  if (total > 0 && total < 1) throw bad("shorter than a second");
  return total;
}

PresetSettings PresetFor(const RunOptions& o) {
  // preview: a first look in a minute or two on a laptop CPU (the README's example), with
  // view-dependent colour (degree 1 at the last level: +0.26 dB held-out on the example at 1.3x
  // the time; docs/tuning.md "View dependence by default where it stays within the bars");
  // default: the paper's 30 iterations per level at a size a CPU still manages, view-dependent
  // colour from level 2 (64^3) on, or at the last level when there are fewer (bonsai: 21.73 /
  // 21.96 dB against 21.27 / 21.20 without, issue 33's base PSNR 5.7x sooner than that base; the
  // example's 2 levels lose 0.28 dB with bands at 32^3; docs/tuning.md "The default preset solves
  // the bands from 64^3");
  // high: full-size images, one more level (meant for a GPU) and view-dependent colour (degree 1
  // at the last level: +0.44 dB held-out on bonsai at 1.9x the time, docs/tuning.md).
  PresetSettings p;
  if (o.preset == "preview") {
    p = {.max_size = 128, .levels = 2, .iterations = 8, .sh_degree = 1, .sh_from_level = 0, .orbit_frames = 24};
  } else if (o.preset == "high") {
    p = {.max_size = 0, .levels = 0, .max_resolution = 1024, .iterations = 30, .sh_degree = 1, .sh_from_level = 0,
         .orbit_frames = 120};
  } else {
    p = {.max_size = 400, .levels = 0, .iterations = 30, .sh_degree = 1, .sh_from_level = 2, .orbit_frames = 60};
  }
  if (o.max_resolution > 0) {  // levels from the photos, within this
    p.max_resolution = o.max_resolution;
    p.levels = 0;
  }
  if (o.max_size > 0) p.max_size = o.max_size;
  if (o.levels > 0) p.levels = o.levels;
  if (o.iterations > 0) p.iterations = o.iterations;
  if (o.sh_degree >= 0) p.sh_degree = o.sh_degree;
  if (o.sh_from_level) {
    p.sh_from_level = *o.sh_from_level;  // the reconstruction checks it against the levels
  } else if (p.levels > 0 && p.sh_from_level > p.levels) {
    p.sh_from_level = 0;  // the preset's level past the set ones: the last
  }
  return p;
}

}  // namespace perf
