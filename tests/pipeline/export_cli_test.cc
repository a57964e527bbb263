// `perf export` and `perf eval` as a user runs them on a small reconstructed synthetic capture:
// every output is there, opens with the library that reads it and has the right size; the
// report's numbers; and the bad inputs (no reconstruction yet, a missing or damaged checkpoint,
// an output that cannot be written, a bad --gt-masks folder), which must write nothing.
#include <gtest/gtest.h>

#include <openvdb/openvdb.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "workspace/image_io.h"
#include "workspace/scene.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

std::string Perf(const std::string& args) { return test::PerfBinary() + " " + args; }

int CountFiles(const fs::path& dir) {
  if (!fs::exists(dir)) return 0;
  int n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir)) n += e.is_regular_file();
  return n;
}

// The one file named `name` under `dir` (outputs keep the photos' sub-folders).
fs::path FindFile(const fs::path& dir, const std::string& name) {
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.path().filename() == name) return e.path();
  }
  ADD_FAILURE() << "no " << name << " under " << dir;
  return dir / name;
}

class ExportCli : public ::testing::Test {
 protected:
  void SetUp() override { test::MakeSyntheticWorkspace(dir_.path(), ws_); }
  void Reconstruct() {
    const auto r = RunCommand(Perf("reconstruct -q " + ws_.string() + " --levels 1 --start-resolution 16 --iterations 4"));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  // Nothing of an export or an evaluation is in the workspace.
  void ExpectNoOutputs() {
    for (const char* p : {"export.json", "volume.vdb", "mesh.ply", "report.json", "report.html"}) {
      EXPECT_FALSE(fs::exists(ws_ / p)) << p;
    }
    EXPECT_EQ(CountFiles(ws_ / "masks"), 0);
    EXPECT_EQ(CountFiles(ws_ / "foreground"), 0);
    EXPECT_EQ(CountFiles(ws_ / "renders"), 0);
  }
  test::TempDir dir_;
  fs::path ws_ = dir_ / "ws";
};

TEST_F(ExportCli, WritesEveryOutputAndEvaluates) {
  Reconstruct();
  auto r = RunCommand(Perf("export " + ws_.string() + " --orbit-frames 3"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("volume.vdb"), std::string::npos) << r.output;

  // 18 photos (15 train, 3 held out): soft and binary masks and cut-outs at the photo's size.
  EXPECT_EQ(CountFiles(ws_ / "masks" / "soft"), 18);
  EXPECT_EQ(CountFiles(ws_ / "masks" / "binary"), 18);
  EXPECT_EQ(CountFiles(ws_ / "foreground"), 18);
  ImageInfo info;
  const Image binary = ReadImage(FindFile(ws_ / "masks" / "binary", "view1.png"), &info);
  EXPECT_EQ(binary.width, 32);
  EXPECT_EQ(binary.channels, 1);
  int inside = 0;
  for (float v : binary.pixels) {
    EXPECT_TRUE(v == 0.f || v == 1.f);
    inside += v == 1.f;
  }
  EXPECT_GT(inside, 0);
  const Image soft = ReadImage(FindFile(ws_ / "masks" / "soft", "view1.png"), &info);
  EXPECT_EQ(info.format, PixelFormat::kUInt16);
  const Image cut = ReadImage(FindFile(ws_ / "foreground", "view1.png"));
  EXPECT_EQ(cut.channels, 4);
  EXPECT_EQ(cut.width, 32);
  for (size_t p = 0; p < binary.pixels.size(); ++p) EXPECT_EQ(cut.pixels[4 * p + 3], binary.pixels[p]);

  // The volume opens with OpenVDB and holds its grids: `perf reconstruct` solves view-dependent
  // colour of degree 1 at its last level by default, exported as three more colour grids.
  openvdb::initialize();
  openvdb::io::File file((ws_ / "volume.vdb").string());
  file.open();
  const openvdb::GridPtrVecPtr grids = file.getGrids();
  std::set<std::string> names;
  for (const auto& g : *grids) names.insert(g->getName());
  EXPECT_EQ(names, (std::set<std::string>{"density", "color", "color_sh1", "color_sh2", "color_sh3"}));
  file.close();
  for (const char* mesh : {"mesh.ply", "mesh.obj", "mesh.mtl", "mesh.png", "mesh.glb"}) {
    EXPECT_GT(fs::file_size(ws_ / mesh), 0u) << mesh;
  }
  EXPECT_EQ(CountFiles(ws_ / "renders" / "test"), 3);
  EXPECT_EQ(CountFiles(ws_ / "renders" / "orbit"), 3);

  const nlohmann::json manifest = nlohmann::json::parse(ReadFileToString(ws_ / "export.json"));
  EXPECT_EQ(manifest["masks"]["count"], 18);
  EXPECT_EQ(manifest["files"].size(), 18u * 3 + 1 + 5 + 3 + 3);  // masks x 3, volume, mesh, renders
  EXPECT_EQ(manifest["mesh"]["texture"]["file"], "mesh.png");
  for (const auto& f : manifest["files"]) EXPECT_TRUE(fs::exists(ws_ / f.get<std::string>())) << f;

  // eval: held-out scores; no true masks in this capture.
  r = RunCommand(Perf("eval " + ws_.string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json report = nlohmann::json::parse(ReadFileToString(ws_ / "report.json"));
  ASSERT_EQ(report["test_views"].size(), 3u);
  EXPECT_GT(report["mean"]["psnr"].get<double>(), 15);
  EXPECT_GT(report["mean"]["ssim"].get<double>(), 0.3);
  EXPECT_LE(report["mean"]["ssim"].get<double>(), 1.0);
  EXPECT_FALSE(report.contains("masks"));
  const std::string html = ReadFileToString(ws_ / "report.html");
  EXPECT_NE(html.find("<svg"), std::string::npos);
  EXPECT_NE(html.find("data:image/png;base64,"), std::string::npos);
  EXPECT_EQ(html.find("http://"), html.find("http://www.w3.org/2000/svg")) << "no network references";

  // --gt-masks with our own binary masks as the truth: a perfect match, through the photo-frame
  // path and the name lookup.
  r = RunCommand(Perf("eval -q " + ws_.string() + " --gt-masks " + (ws_ / "masks" / "binary").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json again = nlohmann::json::parse(ReadFileToString(ws_ / "report.json"));
  EXPECT_EQ(again["masks"]["truth"], "gt-masks");
  EXPECT_EQ(again["masks"]["images"], 18);
  EXPECT_DOUBLE_EQ(again["masks"]["pooled"]["iou"].get<double>(), 1.0);
}

// A photo left out on import (a pose that looks wrong, split "excluded" in scene.json): not
// trained on (recon.json names it), no mask or cut-out (export.json names it), rendered only
// when asked for all views.
TEST_F(ExportCli, APhotoLeftOutOnImportIsNamedAndGetsNoMask) {
  Scene scene = ReadScene(ws_ / "scene.json");
  ASSERT_EQ(scene.images[1].split, Split::kTrain);
  scene.images[1].split = Split::kExcluded;
  scene.images[1].excluded_because = "pose looks wrong: a test";
  WriteScene(ws_ / "scene.json", scene);
  const std::string name = scene.images[1].name;

  auto r = RunCommand(Perf("reconstruct " + ws_.string() + " --levels 1 --start-resolution 16 --iterations 2"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("14 training and 3 held-out views (1 left out on import"), std::string::npos) << r.output;
  const nlohmann::json recon = nlohmann::json::parse(ReadFileToString(ws_ / "recon" / "recon.json"));
  ASSERT_EQ(recon["excluded_views"].size(), 1u);
  EXPECT_EQ(recon["excluded_views"][0]["name"], name);
  EXPECT_EQ(recon["excluded_views"][0]["because"], "pose looks wrong: a test");
  // The first level's fit of every training photo was checked (photo_fit.h), the left-out one not.
  EXPECT_EQ(recon["photo_fits"]["after_level"], 1);
  EXPECT_GT(recon["photo_fits"]["median_psnr"].get<double>(), 0.0);
  ASSERT_TRUE(recon["photo_fits"]["poor"].is_array());
  for (const auto& p : recon["photo_fits"]["poor"]) EXPECT_NE(p["name"], name);

  r = RunCommand(Perf("export " + ws_.string() + " --no-volume --no-mesh --orbit-frames 0"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("no masks for 1 photos left out on import (pose looks wrong): " + name), std::string::npos) << r.output;
  EXPECT_EQ(CountFiles(ws_ / "masks" / "binary"), 17);
  EXPECT_EQ(CountFiles(ws_ / "foreground"), 17);
  const nlohmann::json manifest = nlohmann::json::parse(ReadFileToString(ws_ / "export.json"));
  EXPECT_EQ(manifest["masks"]["not_written"], nlohmann::json::array({name}));

  r = RunCommand(Perf("render -q " + ws_.string() + " --split train --out " + (dir_ / "train").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(CountFiles(dir_ / "train"), 14);
  r = RunCommand(Perf("render -q " + ws_.string() + " --split all --out " + (dir_ / "all").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(CountFiles(dir_ / "all"), 18);
}

TEST_F(ExportCli, BadInputsWriteNothing) {
  // Before perf reconstruct.
  auto r = RunCommand(Perf("export " + ws_.string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("run perf reconstruct"), std::string::npos) << r.output;
  r = RunCommand(Perf("eval " + ws_.string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  ExpectNoOutputs();

  Reconstruct();
  // A checkpoint that is not there.
  r = RunCommand(Perf("export " + ws_.string() + " --checkpoint " + (ws_ / "recon" / "level_7.perfvol").string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("level_7.perfvol"), std::string::npos) << r.output;
  ExpectNoOutputs();

  // A damaged one: the reader names the file and what is wrong.
  const fs::path ck = ws_ / "recon" / "level_0.perfvol";
  const fs::path good = dir_ / "good.perfvol";
  fs::copy_file(ck, good);
  fs::resize_file(ck, fs::file_size(ck) - 100);
  r = RunCommand(Perf("export " + ws_.string()));
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("level_0.perfvol"), std::string::npos) << r.output;
  ExpectNoOutputs();
  fs::copy_file(good, ck, fs::copy_options::overwrite_existing);

  // An output folder that cannot be created (a file is in the way): fails before any work.
  std::ofstream(ws_ / "renders") << "in the way";
  r = RunCommand(Perf("export " + ws_.string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("renders"), std::string::npos) << r.output;
  fs::remove(ws_ / "renders");
  ExpectNoOutputs();

  // Bad option values and a bad --gt-masks folder.
  r = RunCommand(Perf("export " + ws_.string() + " --mask-threshold 1.5"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--mask-threshold"), std::string::npos) << r.output;
  r = RunCommand(Perf("eval " + ws_.string() + " --gt-masks " + (dir_ / "nowhere").string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  fs::create_directories(dir_ / "empty");
  r = RunCommand(Perf("eval " + ws_.string() + " --gt-masks " + (dir_ / "empty").string()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("view0.png"), std::string::npos) << r.output;
  ExpectNoOutputs();
}

}  // namespace
}  // namespace perf
