// A small synthetic capture as a user would bring it: the synthetic scene's views written as
// PNGs plus a NeRF-style transforms.json, imported with `perf import` into a workspace. Shared
// by the CLI tests of reconstruct/render and export/eval.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "workspace/image_io.h"
#include "tests/recon/synthetic_scene.h"
#include "tests/test_util.h"

namespace perf::test {

// Writes the synthetic scene's views as PNGs plus transforms.json (Blender camera axes:
// x right, y up, z backwards), then imports it into `ws`.
inline void MakeSyntheticWorkspace(const std::filesystem::path& dir, const std::filesystem::path& ws) {
  const recon::test::SyntheticScene scene(16, 8, 18, 32, 6);
  nlohmann::json frames = nlohmann::json::array();
  std::vector<const recon::PosedImage*> all;
  // Interleave so the importer's every-6th hold-out picks the scene's test views again.
  size_t t = 0, r = 0;
  for (int v = 0; v < 18; ++v) all.push_back(v % 6 == 0 ? &scene.test[t++] : &scene.train[r++]);
  std::filesystem::create_directories(dir / "images");
  for (size_t i = 0; i < all.size(); ++i) {
    const recon::PosedImage& im = *all[i];
    WriteImage(dir / "images" / (im.name + ".png"), im.image, PixelFormat::kUInt8);
    const float* m = im.camera.world_from_cam;
    nlohmann::json rows = nlohmann::json::array();
    for (int row = 0; row < 3; ++row) rows.push_back({m[4 * row], -m[4 * row + 1], -m[4 * row + 2], m[4 * row + 3]});
    rows.push_back({0, 0, 0, 1});
    frames.push_back({{"file_path", "./images/" + im.name}, {"transform_matrix", rows}});
  }
  const double angle = 2 * std::atan(0.5 * 32 / all[0]->camera.fx);
  std::ofstream(dir / "transforms.json") << nlohmann::json{{"camera_angle_x", angle}, {"frames", frames}}.dump();
  const auto r2 = RunCommand(PerfBinary() + " import -q --nerf " + (dir / "transforms.json").string() +
                             " --holdout 6 --workspace " + ws.string());
  ASSERT_EQ(r2.exit_code, 0) << r2.output;
}

}  // namespace perf::test
