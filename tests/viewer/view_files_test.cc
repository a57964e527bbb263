// What perf view may serve (viewer/view_files.h): the page's files inside the workspace, nothing
// else, whichever way a path tries to leave it.
#include "viewer/view_files.h"

#include <gtest/gtest.h>

#include <fstream>

#include "tests/test_util.h"

namespace perf::viewer {
namespace {

namespace fs = std::filesystem;

TEST(ViewFiles, ServesThePageFilesAndNothingElse) {
  test::TempDir dir;
  const fs::path ws = dir / "ws";
  for (const char* f : {"images/a.png", "images/sub/b.jpg", "masks/binary/a.png", "renders/test/a.png",
                        "foreground/a.png", "mesh.glb", "scene.json", "recon/level_0.perfvol", "images/.hidden.png",
                        "images/notes.txt"}) {
    fs::create_directories((ws / f).parent_path());
    std::ofstream(ws / f) << "x";
  }
  std::ofstream(dir / "secret.png") << "outside";
  fs::create_symlink(dir / "secret.png", ws / "images" / "link.png");

  for (const char* ok : {"images/a.png", "images/sub/b.jpg", "masks/binary/a.png", "renders/test/a.png",
                         "foreground/a.png", "mesh.glb"}) {
    const auto f = ServableFile(ws, ok);
    ASSERT_TRUE(f.has_value()) << ok;
    EXPECT_TRUE(fs::equivalent(*f, ws / ok)) << ok;
  }
  for (const char* bad : {"scene.json",                // not one of the page's files
                          "recon/level_0.perfvol",     // the checkpoints are not served
                          "images/notes.txt",          // not an image or a mesh
                          "images/.hidden.png",        // hidden
                          "images/missing.png",        // not there
                          "images",                    // a folder
                          "../secret.png", "images/../../secret.png", "images/../scene.json",
                          "./images/a.png", "/etc/passwd", "//etc/passwd", "images\\..\\..\\secret.png",
                          "images/link.png",           // a link out of the workspace
                          "", "images/a.png\n"}) {
    EXPECT_FALSE(ServableFile(ws, bad).has_value()) << bad;
  }
  EXPECT_FALSE(ServableFile(ws, std::string(2000, 'a') + ".png").has_value());
  EXPECT_STREQ(ContentTypeOf("a/B.PNG"), "image/png");
  EXPECT_STREQ(ContentTypeOf("mesh.glb"), "model/gltf-binary");
}

}  // namespace
}  // namespace perf::viewer
