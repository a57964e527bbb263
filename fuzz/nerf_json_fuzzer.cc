// libFuzzer target for the NeRF transforms.json reader (sfm_import/nerf_reader.h). Every input
// must either read or throw perf::Error; anything else (a raw nlohmann exception, a crash,
// undefined behaviour, a stack overflow on deep nesting, a hang) is a bug. What reads must give
// finite poses with orthonormal rotations, and finite, positive focal lengths for the json's
// own image size, or Intrinsics must refuse it with perf::Error.
// The reader only resolves image paths (lexically, against "fuzz/"): no file is opened.
// Build, seed and run with scripts/fuzz.sh nerf_json.
//
// Built with -DPERF_FUZZ_MAKE_SEEDS instead, this file is a small program that writes seed
// inputs (a NeRF-synthetic json cut down to a few frames from lego's when given, and an
// instant-ngp one with explicit intrinsics).
#include <Eigen/Dense>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>

#include "common/errors.h"
#include "sfm_import/nerf_reader.h"

#ifndef PERF_FUZZ_MAKE_SEEDS

namespace {

void Require(bool ok, const char* what) {
  if (ok) return;
  std::fprintf(stderr, "%s\n", what);
  std::abort();
}

// Intrinsics for a w x h image: finite and positive focal lengths, or a perf::Error.
void CheckIntrinsics(const perf::NerfTransforms& t, int w, int h) {
  double fx, fy, cx, cy;
  try {
    t.Intrinsics(w, h, "fuzz", &fx, &fy, &cx, &cy);
  } catch (const perf::Error&) {
    return;
  }
  Require(std::isfinite(fx) && fx > 0 && std::isfinite(fy) && fy > 0, "focal length not finite and positive");
  Require(std::isfinite(cx) && std::isfinite(cy), "principal point not finite");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  perf::NerfTransforms t;
  try {
    std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
    t = perf::ReadNerfTransforms(in, "fuzz/transforms.json");
  } catch (const perf::Error&) {
    return 0;
  }
  Require(!t.frames.empty(), "no frames");
  Require(t.fl_x || t.camera_angle_x, "no focal length");
  for (const perf::NerfFrame& f : t.frames) {
    Require(f.world_from_cam.allFinite(), "pose not finite");
    const auto r = f.world_from_cam.leftCols<3>();
    Require((r.transpose() * r).isIdentity(1e-9) && r.determinant() > 0, "rotation not orthonormal");
  }
  Require(!t.width || (*t.width >= 1 && *t.width <= perf::kMaxNerfImageSide), "w out of range");
  Require(!t.height || (*t.height >= 1 && *t.height <= perf::kMaxNerfImageSide), "h out of range");
  // The json's own size, and images of other sizes than the json says.
  CheckIntrinsics(t, t.width.value_or(800), t.height.value_or(800));
  CheckIntrinsics(t, 1, 1);
  CheckIntrinsics(t, perf::kMaxNerfImageSide, perf::kMaxNerfImageSide);
  return 0;
}

#else  // PERF_FUZZ_MAKE_SEEDS

#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json Frame(const std::string& file_path, double x) {
  return {{"file_path", file_path},
          {"transform_matrix", {{1, 0, 0, x}, {0, 0, -1, -4}, {0, 1, 0, 0.5}, {0, 0, 0, 1}}}};
}

}  // namespace

// Usage: make_seeds OUT_DIR [LEGO_TRANSFORMS_JSON]
int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: " << argv[0] << " OUT_DIR [TRANSFORMS_JSON]\n";
    return 2;
  }
  const fs::path out = argv[1];
  fs::create_directories(out);
  json synthetic = {{"camera_angle_x", 0.6911112070083618}, {"camera_angle_y", 0.55}};
  synthetic["frames"] = {Frame("./train/r_0", 0), Frame("./train/r_1.png", 0.5)};
  std::ofstream(out / "synthetic.json") << synthetic.dump(1);
  json ngp = {{"fl_x", 1111.1}, {"fl_y", 1111.1}, {"cx", 400}, {"cy", 400}, {"w", 800}, {"h", 800}};
  ngp["frames"] = {Frame("images/0001.jpg", -1), Frame("images/0002.JPG", 1)};
  std::ofstream(out / "ngp.json") << ngp.dump(1);
  if (argc > 2 && fs::is_regular_file(argv[2])) {
    // The real file, cut to its first frames so that it fits the fuzzer's input size limit.
    try {
      json lego = json::parse(std::ifstream(argv[2]));
      json& frames = lego.at("frames");
      frames.erase(frames.begin() + std::min<std::ptrdiff_t>(3, frames.size()), frames.end());
      std::ofstream(out / "lego_cut.json") << lego.dump(4);
    } catch (const json::exception& e) {
      std::cerr << "no lego seed: " << e.what() << "\n";
    }
  }
  return 0;
}

#endif  // PERF_FUZZ_MAKE_SEEDS
