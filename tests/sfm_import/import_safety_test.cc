// The importer never writes over a user's photo or model and never outside the workspace, however
// the workspace and the names in the model or json are chosen (DESIGN.md "Safety"); and the
// inputs it must refuse are named.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "sfm_import/importer.h"
#include "tests/sfm_import/colmap_fixture.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::ColmapFixture;
using test::ExpectThrows;
using test::ImageName;

// Every regular file under `dir` with its contents.
std::map<fs::path, std::string> Snapshot(const fs::path& dir) {
  std::map<fs::path, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) files[e.path()] = ReadFileToString(e.path());
  }
  return files;
}

TEST(ImportSafety, WorkspaceOverThePhotosIsRefusedAndThePhotosStay) {
  ColmapFixture f;
  const auto before = Snapshot(f.dir.path());
  ImportOptions o = f.Options();
  o.workspace = f.dir.path();  // the COLMAP project folder: images/<name>.png are the photos
  o.max_size = 32;
  const std::string msg = ExpectThrows<InputError>([&] { RunImport(o); });
  EXPECT_NE(msg.find("input"), std::string::npos) << msg;
  EXPECT_NE(msg.find(ImageName(0)), std::string::npos) << msg;
  EXPECT_EQ(Snapshot(f.dir.path()), before);  // not one byte changed, nothing added
}

TEST(ImportSafety, ColmapNamesWithFoldersAndClashingExtensionsStayApart) {
  ColmapFixture f;
  // Two photos whose names differ only by folder, and two whose outputs would both be x.png.
  fs::create_directories(f.images / "a");
  fs::create_directories(f.images / "b");
  const std::vector<std::pair<int, std::string>> renames = {{0, "a/x.png"}, {1, "b/x.png"}, {2, "y.png"}, {3, "y.tif"}};
  for (const auto& [i, name] : renames) {
    colmap::Image& im = f.rec.images.at(static_cast<uint32_t>(i + 1));
    WriteImage(f.images / name, ReadImage(f.images / im.name), PixelFormat::kUInt8);
    fs::remove(f.images / im.name);
    im.name = name;
  }
  colmap::WriteReconstruction(f.model, f.rec, colmap::ModelFormat::kBinary);
  const ImportResult r = RunImport(f.Options());
  std::set<std::string> paths;
  for (const SceneImage& im : r.scene.images) {
    EXPECT_TRUE(IsInsideWorkspace(im.path)) << im.path;
    EXPECT_TRUE(fs::exists(f.dir / "ws" / im.path)) << im.path;
    paths.insert(im.path);
  }
  EXPECT_EQ(paths.size(), r.scene.images.size());  // one file each
  EXPECT_TRUE(paths.count("images/a/x.png") && paths.count("images/b/x.png"));
}

TEST(ImportSafety, NerfPathsOutsideTheJsonFolderStayInTheWorkspace) {
  test::TempDir dir;
  const fs::path json_dir = dir / "scene", ws = dir / "ws";
  fs::create_directories(json_dir / "a");
  fs::create_directories(json_dir / "b");
  fs::create_directories(dir / "elsewhere");
  Image photo(16, 12, 3);
  for (size_t i = 0; i < photo.pixels.size(); ++i) photo.pixels[i] = static_cast<float>(i % 7) / 7.f;
  // file_path as written in the json -> the photo on disk.
  const std::vector<std::pair<std::string, fs::path>> frames = {
      {"../outside", dir / "outside.png"},          // climbs out of the json's folder
      {(dir / "elsewhere" / "abs").string(), dir / "elsewhere" / "abs.png"},  // absolute
      {"a/x", json_dir / "a" / "x.png"},           // these two differ only by folder
      {"b/x", json_dir / "b" / "x.png"}};
  nlohmann::json jf = nlohmann::json::array();
  for (size_t i = 0; i < frames.size(); ++i) {
    WriteImage(frames[i].second, photo, PixelFormat::kUInt8);
    const double x = static_cast<double>(i);
    jf.push_back({{"file_path", frames[i].first},
                  {"transform_matrix", {{1, 0, 0, x}, {0, 1, 0, 0}, {0, 0, 1, 4}, {0, 0, 0, 1}}}});
  }
  std::ofstream(json_dir / "transforms.json") << nlohmann::json{{"camera_angle_x", 0.8}, {"frames", jf}}.dump();
  const auto outside_before = Snapshot(dir.path());
  ImportOptions o;
  o.nerf_json = json_dir / "transforms.json";
  o.workspace = ws;
  o.holdout = 0;
  o.box_center = Eigen::Vector3d(1.5, 0, 0);
  o.box_size = Eigen::Vector3d::Ones();
  const ImportResult r = RunImport(o);
  // Everything written is under ws; nothing outside it changed or appeared.
  auto after = Snapshot(dir.path());
  for (auto it = after.begin(); it != after.end();) {
    it = it->first.string().rfind(ws.string(), 0) == 0 ? after.erase(it) : std::next(it);
  }
  EXPECT_EQ(after, outside_before);
  std::set<std::string> paths;
  for (const SceneImage& im : r.scene.images) {
    EXPECT_TRUE(IsInsideWorkspace(im.path)) << im.path;
    EXPECT_EQ(im.path.rfind("images/", 0), 0u) << im.path;
    EXPECT_TRUE(fs::exists(ws / im.path)) << im.path;
    paths.insert(im.path);
  }
  EXPECT_EQ(paths.size(), 4u);
}

TEST(ImportSafety, WorkspaceSafeNames) {
  EXPECT_EQ(WorkspaceSafeName("a/b.png"), "a/b.png");
  EXPECT_EQ(WorkspaceSafeName("../../x"), "_up_/_up_/x");
  EXPECT_EQ(WorkspaceSafeName("/etc/passwd"), "etc/passwd");
  EXPECT_EQ(WorkspaceSafeName("./a//b/./c"), "a/b/c");
  EXPECT_EQ(WorkspaceSafeName("a\\..\\b"), "a_.._b");
  EXPECT_EQ(WorkspaceSafeName(""), "_");
  EXPECT_EQ(WorkspaceSafeName(".."), "_up_");
  EXPECT_TRUE(IsInsideWorkspace("images/a.png"));
  EXPECT_FALSE(IsInsideWorkspace("images/../../a.png"));
  EXPECT_FALSE(IsInsideWorkspace("/tmp/a.png"));
  EXPECT_FALSE(IsInsideWorkspace(""));
}

TEST(ImportSafety, SymlinkedPhotosAreFound) {
  ColmapFixture f;
  fs::create_directories(f.dir / "store");
  fs::rename(f.images / ImageName(3), f.dir / "store" / "real.png");
  fs::create_symlink(f.dir / "store" / "real.png", f.images / ImageName(3));
  const ImportResult r = RunImport(f.Options());
  EXPECT_EQ(r.scene.images.size(), static_cast<size_t>(test::kNumImages));
}

TEST(ImportSafety, SizeMismatchNamesTheOddPhoto) {
  ColmapFixture f;
  WriteImage(f.images / ImageName(5), Image(50, 40, 3), PixelFormat::kUInt8);
  const std::string msg = ExpectThrows<InputError>([&] { RunImport(f.Options()); });
  EXPECT_NE(msg.find(ImageName(5) + ": size = 50x40"), std::string::npos) << msg;
  EXPECT_NE(msg.find("64x48"), std::string::npos) << msg;
}

TEST(ImportSafety, OutOfRangeOptionsAreRefused) {
  ColmapFixture f;
  const auto refused = [&](const std::function<void(ImportOptions&)>& set, const std::string& option) {
    ImportOptions o = f.Options();
    set(o);
    const std::string msg = ExpectThrows<InputError>([&] { RunImport(o); });
    EXPECT_NE(msg.find(option), std::string::npos) << msg;
    EXPECT_FALSE(fs::exists(f.dir / "ws" / "scene.json"));
  };
  refused([](ImportOptions& o) { o.box_size = Eigen::Vector3d::Constant(1e300); }, "--box-size");
  refused([](ImportOptions& o) { o.box_size = Eigen::Vector3d::Constant(1e-300); }, "--box-size");
  refused([](ImportOptions& o) { o.box_center = Eigen::Vector3d::Constant(1e300); }, "--box-center");
  refused([](ImportOptions& o) { o.bounds.num_shells = 1000; }, "--shells");
  refused([](ImportOptions& o) { o.shell_radii = std::vector<double>{1, 2, 3, 4, 5, 6, 7, 8, 9}; }, "--shell-radii");
}

}  // namespace
}  // namespace perf
