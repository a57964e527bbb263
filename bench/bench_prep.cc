// Prepares the GPU benchmark's data from a workspace made by `perf import` (here, where the
// importer's libraries are): bench.json with every view's pinhole camera, split and size, the
// box and shells, and a copy of the workspace's images (RGB PNGs, already composited over the
// scene's background by the importer), plus the alpha images when every photo had one (then
// perf reconstruct fixes the background and fits the alpha; the benchmark does the same). On the
// GPU machine, bench/decode_images.py turns the PNGs into images.u8 (and alpha.u8), which
// perf_bench_gpu reads (no image library needed there).
//
//   perf_bench_prep --workspace WS --out DIR [--write-u8]
//
// --write-u8 also writes images.u8 here (OpenImageIO), the same bytes decode_images.py writes:
// for checking the data with `perf_bench_gpu --check-data`, or to carry when it is small.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "recon_cuda/data/training_data.h"
#include "recon_cuda/data/volume.h"
#include "workspace/image_io.h"
#include "workspace/scene.h"

using namespace perf;
using namespace perf::recon;
namespace fs = std::filesystem;

int main(int argc, char** argv) {
  CLI::App app{"Prepare perf_bench_gpu's data from a perf import workspace"};
  std::string workspace, out;
  bool write_u8 = false;
  app.add_option("--workspace", workspace, "Workspace made by perf import")->required();
  app.add_option("--out", out, "Output folder (bench.json and images/)")->required();
  app.add_flag("--write-u8", write_u8, "Also decode the images into images.u8 here");
  CLI11_PARSE(app, argc, argv);
  try {
    const Scene scene = ReadScene(fs::path(workspace) / "scene.json");
    const VolumePlacement p = VolumePlacement::FromScene(scene);
    VolumeGeometry::From(p, "scene.json");  // validates box and shells
    fs::create_directories(fs::path(out) / "images");
    nlohmann::json views = nlohmann::json::array();
    int train = 0, test = 0;
    const bool alpha = EveryImageHasAlpha(scene);
    // Copies a workspace file into images/ under a flat name (the relative path with '/' as '_',
    // after `prefix`) and returns its path relative to `out`.
    const auto copy_flat = [&](const std::string& relative, const std::string& prefix) {
      std::string flat = prefix + relative;
      for (char& c : flat) c = c == '/' ? '_' : c;
      fs::copy_file(fs::path(workspace) / relative, fs::path(out) / "images" / flat, fs::copy_options::overwrite_existing);
      return "images/" + flat;
    };
    for (const SceneImage& im : scene.images) {
      const SceneCamera& cam = scene.camera(im.camera_id);
      const PinholeCamera<float> pin = ToPinhole(cam, im.world_from_cam);
      if (im.split == Split::kExcluded) continue;  // a pose that looks wrong: neither trained on nor scored
      const bool is_train = im.split == Split::kTrain;
      (is_train ? train : test) += 1;
      views.push_back({{"name", im.name},
                       {"split", is_train ? "train" : "test"},
                       {"width", cam.width},
                       {"height", cam.height},
                       {"fx", pin.fx},
                       {"fy", pin.fy},
                       {"cx", pin.cx},
                       {"cy", pin.cy},
                       {"world_from_cam", std::vector<float>(pin.world_from_cam, pin.world_from_cam + 12)},
                       {"image", copy_flat(im.path, "")}});
      if (alpha) views.back()["alpha"] = copy_flat(im.alpha_path, "alpha_");
    }
    const nlohmann::json j{
        {"format", "perf-bench-data"},
        {"version", 1},
        {"source", fs::absolute(workspace).string()},
        {"background", {scene.background.x(), scene.background.y(), scene.background.z()}},
        {"alpha", alpha},
        {"placement",
         {{"box_center", std::vector<double>(p.box_center, p.box_center + 3)},
          {"box_rotation", std::vector<double>(p.box_rotation, p.box_rotation + 9)},
          {"box_size", std::vector<double>(p.box_size, p.box_size + 3)},
          {"shell_center", std::vector<double>(p.shell_center, p.shell_center + 3)},
          {"shell_radii", p.shell_radii}}},
        {"views", views}};
    WriteFileAtomically(fs::path(out) / "bench.json", j.dump(1) + "\n");
    if (write_u8) {
      // Every image's pixels from `load`, rounded to 8 bits, one after the other into out/name.
      const auto write_u8_file = [&](const char* name, const std::function<Image(const SceneImage&)>& load) {
        std::ofstream f(fs::path(out) / name, std::ios::binary);
        for (const SceneImage& im : scene.images) {
          const Image image = load(im);
          std::vector<uint8_t> bytes(image.pixels.size());
          for (size_t i = 0; i < bytes.size(); ++i) {
            bytes[i] = static_cast<uint8_t>(std::clamp(image.pixels[i], 0.f, 1.f) * 255.f + 0.5f);
          }
          f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
        }
        if (!f) throw IoError((fs::path(out) / name).string(), "cannot write");
      };
      const Eigen::Vector3d& bg = scene.background;
      write_u8_file("images.u8", [&](const SceneImage& im) {
        return ToRgb(ReadImage(fs::path(workspace) / im.path), {bg.x(), bg.y(), bg.z()});
      });
      if (alpha) {
        write_u8_file("alpha.u8", [&](const SceneImage& im) { return MaskChannel(ReadImage(fs::path(workspace) / im.alpha_path)); });
      }
    }
    std::printf("%s: %d training and %d held-out views; run bench/decode_images.py %s next\n",
                (fs::path(out) / "bench.json").c_str(), train, test, out.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
