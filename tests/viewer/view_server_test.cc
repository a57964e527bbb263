// perf view's server (viewer/view_server.h) over HTTP, in process on a free port: the fixed routes,
// traversal in every spelling, unknown routes, writes refused, huge and malformed requests, two
// clients at once, the log read line by line as a solve appends to it, and a stop mid-request.
#include "viewer/view_server.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <thread>
#include <vector>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "recon_cuda/data/checkpoint.h"
#include "tests/test_util.h"

namespace perf::viewer {
namespace {

namespace fs = std::filesystem;

// A workspace with the files the routes read (the scene need not be a real one for the server).
struct Served {
  test::TempDir dir;
  fs::path ws = dir / "ws";
  std::unique_ptr<ViewServer> server;
  std::thread thread;
  int port = 0;

  Served() {
    fs::create_directories(ws / "images");
    fs::create_directories(ws / "recon");
    std::ofstream(ws / "scene.json") << R"({"format": "perf-scene", "images": []})";
    std::ofstream(ws / "images" / "a.png") << "png bytes";
    std::ofstream(ws / "mesh.glb") << std::string(4 << 20, 'm');  // large enough to be mid-transfer
    std::ofstream(dir / "secret.txt") << "outside";
    ViewOptions o;
    o.workspace = ws;
    o.port = 0;
    server = std::make_unique<ViewServer>(o);
    port = server->Bind();
    thread = std::thread([this] { server->Serve(); });
  }
  ~Served() {
    server->Stop();
    thread.join();
  }
  httplib::Client Client() const {
    httplib::Client c("127.0.0.1", port);
    c.set_connection_timeout(5, 0);
    c.set_read_timeout(10, 0);
    return c;
  }
};

// Sends `raw` on a plain socket and returns what came back (the first KiB).
std::string RawRequest(int port, const std::string& raw) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    ::close(fd);
    return "connect failed";
  }
  ::send(fd, raw.data(), raw.size(), MSG_NOSIGNAL);
  ::shutdown(fd, SHUT_WR);
  char buf[1024];
  std::string got;
  ssize_t n;
  while ((n = ::recv(fd, buf, sizeof(buf), 0)) > 0 && got.size() < 1024) got.append(buf, static_cast<size_t>(n));
  ::close(fd);
  return got;
}

TEST(ViewServer, ServesThePageAndTheWorkspace) {
  Served s;
  auto c = s.Client();
  auto page = c.Get("/");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
  EXPECT_NE(page->body.find("PERF view"), std::string::npos);
  EXPECT_EQ(c.Get("/view.js")->status, 200);
  EXPECT_EQ(c.Get("/view.css")->status, 200);
  auto scene = c.Get("/api/scene");
  EXPECT_EQ(scene->status, 200);
  EXPECT_EQ(scene->body, ReadFileToString(s.ws / "scene.json"));
  EXPECT_EQ(c.Get("/api/report")->status, 404);  // not written yet: the page says so
  EXPECT_EQ(c.Get("/files/images/a.png")->body, "png bytes");
  EXPECT_EQ(c.Get("/files/images/a.png")->get_header_value("Content-Type"), "image/png");
  auto status = c.Get("/api/status");
  EXPECT_NE(status->body.find("\"ws\""), std::string::npos) << status->body;
  if (fs::exists(fs::path(PERF_THREE_DIR) / "build" / "three.min.js")) {
    EXPECT_EQ(c.Get("/lib/three.min.js")->status, 200);
    EXPECT_EQ(c.Get("/lib/GLTFLoader.js")->status, 200);
  }
}

// The fitted volume's routes (field_source.h): the levels listed, a level's payload (gzip'd when
// the client takes it, as httplib's client does by asking), no volume before the first level, a
// bad level refused, a damaged checkpoint named.
TEST(ViewServer, ServesTheFittedVolume) {
  Served s;
  auto c = s.Client();
  EXPECT_EQ(c.Get("/field.js")->status, 200);
  EXPECT_EQ(c.Get("/field_view.js")->status, 200);
  EXPECT_EQ(c.Get("/api/fields")->body, R"({"levels":[],"live":null,"newest":null})");
  EXPECT_EQ(c.Get("/api/field")->status, 404);
  recon::Checkpoint ck;
  ck.shape = recon::VolumeShape(8, 2, 2);
  ck.placement.shell_radii = {2, 4};
  ck.params.assign(ck.shape.ParamCount(), 0.5f);
  recon::WriteCheckpoint(recon::CheckpointPath(s.ws, 0), ck);
  EXPECT_NE(c.Get("/api/fields")->body.find(R"("newest":0)"), std::string::npos);
  httplib::Headers plain{{"Accept-Encoding", "identity"}};
  auto raw = c.Get("/api/field?level=0", plain);
  ASSERT_TRUE(raw);
  EXPECT_EQ(raw->status, 200);
  EXPECT_EQ(raw->get_header_value("Content-Type"), "application/octet-stream");
  EXPECT_EQ(raw->body.substr(0, 7), "PERFFLD");
  EXPECT_EQ(raw->body.size(), 256u + 2 * ck.params.size());
  auto gz = c.Get("/api/field", {{"Accept-Encoding", "gzip"}});
  ASSERT_TRUE(gz);
  EXPECT_EQ(gz->status, 200);
  EXPECT_EQ(gz->body, raw->body) << "httplib's client undid the gzip";
  for (const char* bad : {"/api/field?level=x", "/api/field?level=-1", "/api/field?level=123"}) {
    EXPECT_EQ(c.Get(bad)->status, 400) << bad;
  }
  EXPECT_EQ(c.Get("/api/field?level=3")->status, 404);
  std::ofstream(recon::CheckpointPath(s.ws, 1)) << "not a checkpoint";
  auto damaged = c.Get("/api/field?level=1");
  EXPECT_EQ(damaged->status, 422);
  EXPECT_NE(damaged->body.find("level_1.perfvol"), std::string::npos) << damaged->body;
}

TEST(ViewServer, RefusesTraversalUnknownRoutesAndWrites) {
  Served s;
  auto c = s.Client();
  for (const char* path : {"/files/../secret.txt", "/files/%2e%2e/secret.txt", "/files/..%2fsecret.txt",
                           "/files/images/..%2F..%2Fsecret.txt", "/files/%2Fetc%2Fpasswd", "/files//etc/passwd",
                           "/files/scene.json", "/files/images/%00a.png", "/../secret.txt", "/%2e%2e/secret.txt",
                           "/etc/passwd", "/nope", "/api/nope", "/files/", "/lib/../../etc/passwd"}) {
    auto r = c.Get(path);
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, 404) << path;
    EXPECT_EQ(r->body.find("outside"), std::string::npos) << path;
  }
  EXPECT_EQ(c.Post("/api/scene", "{}", "application/json")->status, 405);
  EXPECT_EQ(c.Delete("/files/images/a.png")->status, 405);
  EXPECT_TRUE(fs::exists(s.ws / "images" / "a.png"));
}

TEST(ViewServer, AnswersHugeAndMalformedRequestsAndGoesOn) {
  Served s;
  auto c = s.Client();
  auto huge = c.Post("/api/scene", std::string(1 << 20, 'x'), "text/plain");
  ASSERT_TRUE(huge);
  EXPECT_EQ(huge->status, 413);
  // Garbage, an over-long request line and nothing at all: refused (an error status, or the
  // connection closed without an answer), never a page.
  for (const std::string& raw : {std::string("THIS IS NOT HTTP\r\n\r\n"),
                                 "GET /" + std::string(100000, 'a') + " HTTP/1.1\r\nHost: x\r\n\r\n",
                                 std::string("GET / HTTP/1.1\r\nHost: x\r\nContent-Length: -5\r\n\r\n"),
                                 std::string()}) {
    const std::string got = RawRequest(s.port, raw);
    EXPECT_TRUE(got.empty() || got.rfind("HTTP/1.1 4", 0) == 0) << raw.substr(0, 40) << " -> " << got.substr(0, 80);
  }
  EXPECT_EQ(c.Get("/api/log?from=abc")->status, 400);
  EXPECT_EQ(c.Get("/api/log?from=99999999999999999999")->status, 400);
  EXPECT_EQ(c.Get("/api/scene")->status, 200);  // still serving
}

TEST(ViewServer, TwoClientsAtOnce) {
  Served s;
  std::atomic<int> ok{0};
  std::vector<std::thread> clients;
  for (int k = 0; k < 2; ++k) {
    clients.emplace_back([&] {
      auto c = s.Client();
      for (int i = 0; i < 25; ++i) {
        auto r = c.Get(i % 2 ? "/api/scene" : "/files/images/a.png");
        ok += r && r->status == 200;
      }
    });
  }
  for (auto& t : clients) t.join();
  EXPECT_EQ(ok.load(), 50);
}

// Clients that send a request a byte at a time, more of them than a pool has threads, do not
// starve the others: a normal request is still answered within 2 s.
TEST(ViewServer, SlowClientsDoNotStarveTheOthers) {
  Served s;
  std::vector<int> slow;
  for (int k = 0; k < 24; ++k) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<uint16_t>(s.port));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    ASSERT_EQ(::send(fd, "G", 1, MSG_NOSIGNAL), 1);  // the start of a request line, and no more for now
    slow.push_back(fd);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // all of them accepted and read from
  auto c = s.Client();
  c.set_read_timeout(3, 0);
  const auto start = std::chrono::steady_clock::now();
  const auto r = c.Get("/api/scene");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(r) << "no answer";
  EXPECT_EQ(r->status, 200);
  EXPECT_LT(seconds, 2.0);
  for (int fd : slow) ::close(fd);
}

TEST(ViewServer, ReadsTheLogLineByLineAsItGrows) {
  Served s;
  auto c = s.Client();
  auto empty = c.Get("/api/log");
  EXPECT_EQ(empty->status, 200);
  EXPECT_EQ(empty->body, "");
  EXPECT_EQ(empty->get_header_value("X-Next-Offset"), "0");
  const fs::path log = s.ws / "recon" / "log.jsonl";
  std::ofstream(log) << "{\"event\":\"iteration\",\"iteration\":0}\n{\"event\":\"iter";  // a line being written
  auto first = c.Get("/api/log?from=0");
  EXPECT_EQ(first->body, "{\"event\":\"iteration\",\"iteration\":0}\n");
  const std::string next = first->get_header_value("X-Next-Offset");
  EXPECT_EQ(next, std::to_string(first->body.size()));
  std::ofstream(log, std::ios::app) << "ation\",\"iteration\":1}\n";
  auto second = c.Get(("/api/log?from=" + next).c_str());
  EXPECT_EQ(second->body, "{\"event\":\"iteration\",\"iteration\":1}\n");
  EXPECT_EQ(c.Get("/api/log?from=100000")->body, "");
}

TEST(ViewServer, StopsMidRequestWithoutHarm) {
  Served s;
  std::thread client([&] {
    auto c = s.Client();
    for (int i = 0; i < 20; ++i) c.Get("/files/mesh.glb");  // answered or cut: either is fine
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  s.server->Stop();
  client.join();
  auto c = s.Client();
  EXPECT_FALSE(c.Get("/api/scene"));  // nobody listens any more
}

TEST(ViewServer, NamesAMissingWorkspaceAndABusyPort) {
  test::TempDir dir;
  ViewOptions o;
  o.workspace = dir / "nothing";
  try {
    ViewServer server(o);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("scene.json"), std::string::npos) << e.what();
  }
  Served s;
  ViewOptions again;
  again.workspace = s.ws;
  again.port = s.port;
  ViewServer second(again);
  try {
    second.Bind();
    FAIL() << "expected the port to be busy";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(std::to_string(s.port)), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--port"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(IsLoopback("127.0.0.1"));
  EXPECT_FALSE(IsLoopback("0.0.0.0"));
}

}  // namespace
}  // namespace perf::viewer
