// perf view's page as a person sees it, in Debian's headless Chromium: `perf view` over a workspace
// that `perf run` made from the shipped example; the DOM once the page settled (a frustum per
// photo, the held-out table as report.json has it, the mesh loaded) and a screenshot of the mesh
// alone (the canvas drew it). Ctrl-C stops the server cleanly. Skips where chromium is missing.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <map>
#include <regex>
#include <set>
#include <thread>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "recon_cuda/data/checkpoint.h"
#include "tests/pipeline/synthetic_workspace.h"
#include "tests/test_util.h"
#include "workspace/image_io.h"
#include "workspace/scene.h"

namespace perf {
namespace {

namespace fs = std::filesystem;
using test::RunCommand;

constexpr const char* kChromium = "/usr/bin/chromium";

std::string Chromium(const std::string& args, int budget_ms = 30000) {
  // SwiftShader: WebGL without a GPU. The budget lets the page's fetches and frames run.
  return std::string(kChromium) + " --headless=new --no-sandbox --disable-dev-shm-usage --use-angle=swiftshader "
                                  "--enable-unsafe-swiftshader --hide-scrollbars --virtual-time-budget=" +
         std::to_string(budget_ms) + " " + args;
}

// A perf command in the background (`args` end with a --port 0 or --view-port 0), its output in
// `log`, and the port it printed in a line matching `url` (0 when none came within 10 s).
struct Background {
  int pid = 0, port = 0;
  fs::path log;
  Background(const std::string& args, const fs::path& log_file, const std::regex& url) : log(log_file) {
    pid = std::stoi(RunCommand(test::PerfBinary() + " " + args + " > " + log.string() + " 2>&1 & echo $!").output);
    for (int i = 0; i < 100 && port == 0; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      std::smatch m;
      const std::string text = fs::exists(log) ? ReadFileToString(log) : "";
      if (std::regex_search(text, m, url)) port = std::stoi(m[1]);
    }
  }
  std::string Url() const { return "http://127.0.0.1:" + std::to_string(port) + "/"; }
  std::string Output() const { return fs::exists(log) ? ReadFileToString(log) : ""; }
  // Ctrl-C; true when it exited within 5 s.
  bool Interrupt() {
    ::kill(pid, SIGINT);
    for (int i = 0; i < 50; ++i) {
      if (::kill(pid, 0) != 0) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
  }
  ~Background() {
    if (pid > 0 && ::kill(pid, 0) == 0) ::kill(pid, SIGKILL);
  }
};

std::string Attribute(const std::string& dom, const std::string& name) {
  std::smatch m;
  const std::regex re(name + R"(=\"([^\"]*)\")");
  return std::regex_search(dom, m, re) ? m[1].str() : "";
}

TEST(ViewPage, ShowsTheCamerasTheScoresAndTheMesh) {
  if (!fs::exists(kChromium)) GTEST_SKIP() << "chromium is not installed (scripts/setup.sh installs it)";
  const fs::path example = fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini";
  test::TempDir dir;
  const fs::path ws = dir / "ws";
  // --sh-degree 0: what the page shows does not depend on the preview's view dependence, which
  // only makes the run longer.
  const auto run = RunCommand(test::PerfBinary() + " run --colmap " + (example / "sparse" / "0").string() +
                              " --images " + (example / "images").string() + " --workspace " + ws.string() +
                              " --preset preview --max-size 96 --levels 2 --iterations 3 --sh-degree 0 --log-level quiet");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  ASSERT_TRUE(fs::exists(ws / "mesh.glb"));

  Background view("view " + ws.string() + " --port 0", dir / "view.log", std::regex(R"(http://127\.0\.0\.1:(\d+)/)"));
  ASSERT_GT(view.port, 0) << view.Output();
  const std::string url = view.Url();
  EXPECT_NE(view.Output().find("ssh -L " + std::to_string(view.port)), std::string::npos);

  const auto dom = RunCommand(Chromium("--dump-dom " + url) + " 2>/dev/null");
  ASSERT_EQ(dom.exit_code, 0) << dom.output;
  EXPECT_EQ(Attribute(dom.output, "data-ready"), "1") << dom.output.substr(0, 2000);
  const Scene scene = ReadScene(ws / "scene.json");
  EXPECT_EQ(Attribute(dom.output, "data-cameras"), std::to_string(scene.images.size()));
  EXPECT_EQ(Attribute(dom.output, "data-mesh"), "loaded");
  EXPECT_NE(Attribute(dom.output, "data-iterations"), "");
  const nlohmann::json report = nlohmann::json::parse(ReadFileToString(ws / "report.json"));
  EXPECT_EQ(Attribute(dom.output, "data-views"), std::to_string(report["test_views"].size()));
  for (const auto& v : report["test_views"]) {  // the table's rows as report.json has them
    char row[256];
    std::snprintf(row, sizeof(row), "<td>%s</td><td>%.2f</td><td>%.3f</td>", v["name"].get<std::string>().c_str(),
                  v["psnr"].get<double>(), v["ssim"].get<double>());
    EXPECT_NE(dom.output.find(row), std::string::npos) << row;
  }

  // The mesh alone: the canvas (the top-left 60 % of the page) differs from its background.
  const fs::path shot = dir / "mesh.png";
  const auto taken = RunCommand(Chromium("--window-size=1200,800 --screenshot=" + shot.string() + " '" + url +
                                         "?layers=mesh'") + " 2>/dev/null");
  ASSERT_EQ(taken.exit_code, 0) << taken.output;
  const Image image = ReadImage(shot);
  int drawn = 0, canvas = 0;
  for (int y = 80; y < std::min(image.height, 560); ++y) {
    for (int x = 20; x < image.width * 55 / 100; ++x) {
      const float* p = &image.pixels[(static_cast<size_t>(y) * image.width + x) * image.channels];
      const float d = std::abs(p[0] - 0x20 / 255.f) + std::abs(p[1] - 0x23 / 255.f) + std::abs(p[2] - 0x2a / 255.f);
      ++canvas;
      drawn += d > 0.15f;
    }
  }
  EXPECT_GT(drawn, canvas / 100) << drawn << " of " << canvas << " pixels drawn";

  EXPECT_TRUE(view.Interrupt());
  EXPECT_NE(view.Output().find("stopped"), std::string::npos) << view.Output();
}

// data-field-png's image (a PNG data URL) as RGB, through a file OpenImageIO reads.
Image FieldImage(const std::string& dom, const fs::path& file) {
  const std::string url = Attribute(dom, "data-field-png");
  const std::string prefix = "data:image/png;base64,";
  if (url.rfind(prefix, 0) != 0) return {};
  std::string bytes;
  int bits = 0, acc = 0;
  for (char ch : url.substr(prefix.size())) {
    const char* at = std::strchr("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/", ch);
    if (ch == '=' || !at || ch == '\0') break;
    acc = (acc << 6) | static_cast<int>(at - "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/");
    if ((bits += 6) >= 8) bytes.push_back(static_cast<char>((acc >> (bits -= 8)) & 0xff));
  }
  WriteFileAtomically(file, bytes);
  const Image rgba = ReadImage(file);
  Image rgb(rgba.width, rgba.height, 3);
  for (int y = 0; y < rgb.height; ++y)
    for (int x = 0; x < rgb.width; ++x)
      for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = rgba.at(x, y, c) / std::max(rgba.at(x, y, 3), 1e-6f);
  return rgb;
}

double Psnr(const Image& a, const Image& b) {
  double sse = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) sse += (a.pixels[i] - b.pixels[i]) * (a.pixels[i] - b.pixels[i]);
  return sse > 0 ? -10 * std::log10(sse / a.pixels.size()) : 99;
}

// The page's field against perf render of the same camera and checkpoint: the two marchers
// (viewer/page/field.js and recon_cuda/core) agree to >= 35 dB (measured 71-72 dB: the page's half
// floats and the last bit of exp), with the render rule off and on. A held-out view of the
// example's two levels (a dense 32^3 level without bands; a sparse 64^3 one with degree-1 bands,
// learned shells), and of a synthetic capture fitted with the shells fixed at the background.
TEST(ViewPage, TheFieldIsWhatPerfRenders) {
  if (!fs::exists(kChromium)) GTEST_SKIP() << "chromium is not installed (scripts/setup.sh installs it)";
  const fs::path example = fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini";
  test::TempDir dir;
  const fs::path ws = dir / "ws", synthetic = dir / "synthetic";
  auto r = RunCommand(test::PerfBinary() + " run --colmap " + (example / "sparse" / "0").string() + " --images " +
                      (example / "images").string() + " --workspace " + ws.string() +
                      " --preset preview --max-size 96 --levels 2 --iterations 3 --exposure off --refine-poses off"
                      " --log-level quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  test::MakeSyntheticWorkspace(dir / "capture", synthetic);
  r = RunCommand(test::PerfBinary() + " reconstruct " + synthetic.string() +
                 " --levels 1 --start-resolution 16 --iterations 3 --background fixed --no-grow-box -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const recon::Checkpoint sparse = recon::ReadCheckpoint(recon::CheckpointPath(ws, 1));
  ASSERT_TRUE(sparse.shape.sparse());
  ASSERT_EQ(sparse.shape.sh_degree, 1);
  ASSERT_FALSE(recon::ReadCheckpoint(recon::CheckpointPath(ws, 0)).shape.sparse());
  struct Case {
    fs::path ws;
    int level;
    float rule;
  };
  for (const Case& k : {Case{ws, 0, 0.f}, Case{ws, 1, 0.f}, Case{ws, 1, 0.7f}, Case{synthetic, 0, 0.f}}) {
    SCOPED_TRACE(testing::Message() << k.ws.filename() << " level " << k.level << ", rule " << k.rule);
    const Scene scene = ReadScene(k.ws / "scene.json");
    std::string name;
    for (const SceneImage& im : scene.images) {
      if (im.split == Split::kTest && name.empty()) name = im.name;
    }
    ASSERT_FALSE(name.empty());
    const fs::path renders = dir / StrCat("renders_", k.ws.filename().string(), k.level, k.rule > 0);
    r = RunCommand(test::PerfBinary() + " render " + k.ws.string() + " --checkpoint " +
                   recon::CheckpointPath(k.ws, k.level).string() + " --view " + name + " --min-box-opacity " +
                   std::to_string(k.rule) + " -o " + renders.string() + " -q");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const Image render = ReadImage(renders / fs::path(name).filename().replace_extension(".png"));
    Background view("view " + k.ws.string() + " --port 0", dir / "view.log", std::regex(R"(http://127\.0\.0\.1:(\d+)/)"));
    ASSERT_GT(view.port, 0) << view.Output();
    const auto dom = RunCommand(Chromium("--dump-dom '" + view.Url() + "?field=" + name + "&dump=1&level=" +
                                         std::to_string(k.level) + "&rule=" + std::to_string(k.rule) + "'") +
                                " 2>/dev/null");
    ASSERT_EQ(Attribute(dom.output, "data-field-ready"), "1") << dom.output.substr(0, 3000);
    EXPECT_EQ(Attribute(dom.output, "data-field-error"), "");
    const Image field = FieldImage(dom.output, dir / "field.png");
    ASSERT_EQ(field.width, render.width);
    ASSERT_EQ(field.height, render.height);
    const double psnr = Psnr(field, render);
    std::printf("field vs perf render: %.2f dB\n", psnr);
    EXPECT_GE(psnr, 35.0);
    EXPECT_TRUE(view.Interrupt());
  }
}

// `perf run --view` on a small capture: the page follows the solve (its iteration counter advances
// and it shows the newest preview), says when the run finished, and Ctrl-C then ends the command.
TEST(ViewPage, FollowsALiveRun) {
  if (!fs::exists(kChromium)) GTEST_SKIP() << "chromium is not installed (scripts/setup.sh installs it)";
  const fs::path example = fs::path(PERF_SOURCE_DIR) / "examples" / "bonsai_mini";
  test::TempDir dir;
  Background run("run --colmap " + (example / "sparse" / "0").string() + " --images " + (example / "images").string() +
                     " --workspace " + (dir / "ws").string() +
                     " --preset preview --max-size 96 --levels 2 --iterations 8 --sh-degree 0 --view --view-port 0",
                 dir / "run.log", std::regex(R"(its page is at http://127\.0\.0\.1:(\d+)/)"));
  ASSERT_GT(run.port, 0) << run.Output();
  const std::string page = run.Url();
  // Looks at the page now and then while the solve goes on, its field at a held-out photo's camera
  // (the import's first held-out one: every 8th by name from the first).
  std::vector<int> seen;
  std::map<std::string, std::pair<int, double>> volumes;  // live version: level, PSNR against the photo
  bool preview = false, finished = false;
  for (int look = 0; look < 40 && !finished; ++look) {
    const auto dom = RunCommand(Chromium("--dump-dom '" + page + "?field=DSCF5608.JPG'", 5000) + " 2>/dev/null");
    const std::string state = Attribute(dom.output, "data-state");
    const std::string it = Attribute(dom.output, "data-iterations");
    if (state == "running" && !it.empty()) seen.push_back(std::stoi(it));
    const std::string version = Attribute(dom.output, "data-field-version");
    if (version.rfind("live", 0) == 0 && !Attribute(dom.output, "data-field-psnr").empty()) {
      volumes[version] = {std::stoi(Attribute(dom.output, "data-field-level")),
                          std::stod(Attribute(dom.output, "data-field-psnr"))};
    }
    preview = preview || dom.output.find("src=\"/files/preview/") != std::string::npos;
    finished = state == "finished";
    if (finished) {
      EXPECT_NE(dom.output.find("finished; the server stays up"), std::string::npos);
    }
  }
  EXPECT_TRUE(finished) << run.Output();
  ASSERT_GE(seen.size(), 2u) << "the page never saw the solve running twice";
  EXPECT_GT(seen.back(), seen.front()) << "the iteration counter did not advance";
  EXPECT_TRUE(preview);
  // The page drew the solver's volume as it went: a new one in each level, better against the photo
  // at the end than at the start.
  std::set<int> levels;
  for (const auto& [version, v] : volumes) levels.insert(v.first);
  EXPECT_EQ(levels, (std::set<int>{0, 1})) << volumes.size() << " live volumes seen";
  ASSERT_GE(volumes.size(), 2u);
  const auto by_version = [](const auto& a, const auto& b) {
    return std::stoi(a.first.substr(5)) < std::stoi(b.first.substr(5));
  };
  const auto first = std::min_element(volumes.begin(), volumes.end(), by_version);
  const auto last = std::max_element(volumes.begin(), volumes.end(), by_version);
  EXPECT_GT(last->second.second, first->second.second) << "PSNR against the photo: " << first->second.second
                                                        << " dB at " << first->first << ", " << last->second.second
                                                        << " dB at " << last->first;
  EXPECT_NE(run.Output().find("the page stays at"), std::string::npos);
  EXPECT_TRUE(run.Interrupt());
}

}  // namespace
}  // namespace perf
