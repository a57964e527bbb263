// libFuzzer target for the checkpoint reader (recon_cuda/data/checkpoint.h). Every input must either
// read or throw perf::Error; anything else (another exception such as bad_alloc, a crash,
// undefined behaviour, a hang, an allocation out of proportion to the input) is a bug. A
// checkpoint that reads must write and read back to the same bytes.
// Build, seed and run with scripts/fuzz.sh checkpoint.
//
// Built with -DPERF_FUZZ_MAKE_SEEDS instead, this file is a small program that writes seed
// checkpoints (the smallest shape, a small one with two shells, one with every shell, a sparse
// one).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>

#include "common/errors.h"
#include "recon_cuda/data/checkpoint.h"

namespace {

using perf::recon::Checkpoint;

std::string Write(const Checkpoint& c) {
  std::ostringstream out;
  perf::recon::WriteCheckpoint(out, c);
  return out.str();
}

}  // namespace

#ifndef PERF_FUZZ_MAKE_SEEDS

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Checkpoint c;
  try {
    std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
    c = perf::recon::ReadCheckpoint(in, "fuzz");
  } catch (const perf::Error&) {
    return 0;
  }
  // What reads must be placeable as the ray math and the exports take it (in float): sides
  // positive and finite, the rotation a rotation. (A header with sides of 1e300 or 1e-300, or a
  // zero rotation, once read and failed later in OpenVDB.)
  const perf::recon::VolumePlacement& p = c.placement;
  for (double side : p.box_size) {
    const float f = static_cast<float>(side);
    if (!(f > 0 && std::isfinite(f))) {
      std::fprintf(stderr, "checkpoint read with a box side of %g\n", side);
      std::abort();
    }
  }
  // Positions in float, and values, not only the header: a NaN parameter read without a word once
  // scored as a perfect PSNR.
  for (double v : p.box_center) {
    if (!std::isfinite(static_cast<float>(v))) {
      std::fprintf(stderr, "checkpoint read with a box centre of %g\n", v);
      std::abort();
    }
  }
  for (float v : c.params) {
    if (!std::isfinite(v)) {
      std::fprintf(stderr, "checkpoint read with a parameter of %g\n", v);
      std::abort();
    }
  }
  const double* r = p.box_rotation;
  const double det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6]) +
                     r[2] * (r[3] * r[7] - r[4] * r[6]);
  if (!(std::abs(det - 1) < 1e-3)) {
    std::fprintf(stderr, "checkpoint read with a box rotation of determinant %g\n", det);
    std::abort();
  }
  // What reads must be writable, and rewriting it must be stable (the unused shell radii are
  // written as 0, so compare the rewritten bytes, not the input). No try: any exception is a
  // finding.
  const std::string once = Write(c);
  std::istringstream in(once);
  if (Write(perf::recon::ReadCheckpoint(in, "rewritten")) != once) {
    std::fprintf(stderr, "checkpoint rewrite is not stable\n");
    std::abort();
  }
  return 0;
}

#else  // PERF_FUZZ_MAKE_SEEDS

#include <filesystem>
#include <fstream>
#include <iostream>

namespace {

namespace fs = std::filesystem;

Checkpoint Make(perf::recon::VolumeShape shape, int level, int solver) {
  Checkpoint c;
  c.level = level;
  c.iterations = 8;
  c.solver = solver;
  c.shape = shape;
  c.placement.box_center[0] = 0.25;
  c.placement.box_size[1] = 2;
  c.placement.shell_center[2] = -0.5;
  for (int k = 0; k < shape.num_shells; ++k) c.placement.shell_radii.push_back(2.0 * (k + 1));
  c.params.resize(static_cast<size_t>(shape.ParamCount()));
  for (size_t i = 0; i < c.params.size(); ++i) c.params[i] = 0.01f * static_cast<float>(i % 97);
  return c;
}

}  // namespace

// Usage: make_seeds OUT_DIR
int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: " << argv[0] << " OUT_DIR\n";
    return 2;
  }
  const fs::path out = argv[1];
  fs::create_directories(out);
  std::ofstream(out / "smallest.perfvol", std::ios::binary) << Write(Make({1, 1, 1}, 0, 0));
  std::ofstream(out / "small.perfvol", std::ios::binary) << Write(Make({4, 2, 2}, 1, 1));
  std::ofstream(out / "all_shells.perfvol", std::ios::binary) << Write(Make({2, 2, perf::recon::kMaxShells}, 2, 0));
  std::vector<uint8_t> active(8, 0);
  active[2] = active[5] = 1;
  const auto bricks = std::make_shared<const perf::recon::BrickGrid>(perf::recon::MakeBrickGrid(16, active));
  std::ofstream(out / "sparse.perfvol", std::ios::binary) << Write(Make({16, 1, 1, bricks}, 1, 0));
  return 0;
}

#endif  // PERF_FUZZ_MAKE_SEEDS
