#include "viewer/view_server.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <fstream>
#include <mutex>
#include <thread>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "sfm_import/colmap_model.h"
#include "viewer/field_source.h"
#include "viewer/page_assets.h"
#include "viewer/view_files.h"
#include "workspace/scene.h"

// Last: glibc's <resolv.h>, which it includes, defines _res, a parameter name in Eigen.
#include <httplib.h>

namespace perf::viewer {

namespace fs = std::filesystem;

namespace {

// The most sparse points the page gets (every k-th beyond it): enough to see the scene.
constexpr size_t kMaxPoints = 50000;
// A request larger than this is refused (the page sends none with a body).
constexpr size_t kMaxPayload = 64 * 1024;

void NotFound(httplib::Response& res, const std::string& what) {
  res.status = 404;
  res.set_content(nlohmann::json{{"missing", what}}.dump(), "application/json");
}

// The file's whole text, or nullopt when it is not there (a run still writing it: next poll).
std::optional<std::string> ReadIfThere(const fs::path& file) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return std::nullopt;
  try {
    return ReadFileToString(file);
  } catch (const Error&) {
    return std::nullopt;
  }
}

// The sparse points of the scene's COLMAP model (read-only), as {"xyz": [...], "rgb": [...]}.
nlohmann::json SparsePoints(const fs::path& workspace) {
  nlohmann::json out = {{"xyz", nlohmann::json::array()}, {"rgb", nlohmann::json::array()}, {"count", 0}};
  try {
    const Scene scene = ReadScene(workspace / "scene.json");
    if (scene.source.type != "colmap") return out;
    const colmap::Reconstruction rec = colmap::ReadReconstruction(scene.source.path);
    const size_t step = std::max<size_t>(1, (rec.points3D.size() + kMaxPoints - 1) / kMaxPoints);
    size_t k = 0, kept = 0;
    for (const auto& [id, p] : rec.points3D) {
      if (k++ % step != 0) continue;
      for (double v : p.xyz) out["xyz"].push_back(v);
      for (uint8_t v : p.rgb) out["rgb"].push_back(v);
      ++kept;
    }
    out["count"] = kept;
    out["total"] = rec.points3D.size();
  } catch (const Error& e) {
    out["error"] = e.what();
  }
  return out;
}

// Each connection on a thread of its own, at most kMaxConnections at once (the next waits, in the
// listen backlog, for one to end). httplib's default is a fixed pool of about one thread per core,
// which as many clients sending a byte a second hold for as long as they keep sending.
class ConnectionThreads : public httplib::TaskQueue {
 public:
  static constexpr int kMaxConnections = 64;
  void enqueue(std::function<void()> fn) override {
    std::unique_lock lock(mutex_);
    idle_.wait(lock, [&] { return running_ < kMaxConnections; });
    ++running_;
    std::thread([this, task = std::move(fn)]() mutable {
      {
        const std::function<void()> run = std::move(task);
        run();
      }
      const std::lock_guard done(mutex_);
      --running_;
      idle_.notify_all();
    }).detach();
  }
  // Returns once every connection has ended (httplib deletes the queue next).
  void shutdown() override {
    std::unique_lock lock(mutex_);
    idle_.wait(lock, [&] { return running_ == 0; });
  }

 private:
  std::mutex mutex_;
  std::condition_variable idle_;
  int running_ = 0;
};

}  // namespace

struct ViewServer::Impl {
  ViewOptions o;
  httplib::Server server;
  int port = 0;
  std::once_flag points_once;
  std::string points;
  std::function<nlohmann::json()> live;  // set before Bind
  std::unique_ptr<FieldSource> fields;    // /api/fields, /api/field
  // Stop() may come before Serve() listens (httplib's stop() is a no-op until then).
  std::atomic<bool> stop_requested{false}, serving{false};

  void Routes();
  void FieldRoutes();
  void ServeJson(const char* route, fs::path file);
  void ServeLibrary(const char* route, fs::path file);
};

void ViewServer::Impl::ServeJson(const char* route, fs::path file) {
  server.Get(route, [file = o.workspace / file](const httplib::Request&, httplib::Response& res) {
    const std::optional<std::string> text = ReadIfThere(file);
    if (!text) return NotFound(res, file.filename().string());
    res.set_header("Cache-Control", "no-store");
    res.set_content(*text, "application/json");
  });
}

void ViewServer::Impl::ServeLibrary(const char* route, fs::path file) {
  server.Get(route, [file = o.three_dir / file](const httplib::Request&, httplib::Response& res) {
    const std::optional<std::string> text = ReadIfThere(file);
    if (!text) return NotFound(res, file.string() + " (install Debian's libjs-three: scripts/setup.sh)");
    res.set_content(*text, "text/javascript");
  });
}

void ViewServer::Impl::Routes() {
  const auto page = [](std::string_view body, const char* type) {
    return [body, type](const httplib::Request&, httplib::Response& res) {
      res.set_content(std::string(body), type);
    };
  };
  server.Get("/", page(kIndexHtml, "text/html; charset=utf-8"));
  server.Get("/view.js", page(kViewJs, "text/javascript"));
  server.Get("/view.css", page(kViewCss, "text/css"));
  server.Get("/field.js", page(kFieldJs, "text/javascript"));
  server.Get("/field_view.js", page(kFieldViewJs, "text/javascript"));
  ServeLibrary("/lib/three.min.js", "build/three.min.js");
  ServeLibrary("/lib/OrbitControls.js", "examples/js/controls/OrbitControls.js");
  ServeLibrary("/lib/GLTFLoader.js", "examples/js/loaders/GLTFLoader.js");
  ServeJson("/api/scene", "scene.json");
  ServeJson("/api/report", "report.json");
  ServeJson("/api/recon", fs::path("recon") / "recon.json");
  ServeJson("/api/export", "export.json");
  ServeJson("/api/run", "run.json");
  server.Get("/api/status", [this](const httplib::Request&, httplib::Response& res) {
    nlohmann::json status{{"workspace", o.workspace.filename().string()}, {"live", live != nullptr}};
    if (live) status.update(live());
    res.set_header("Cache-Control", "no-store");
    res.set_content(status.dump(), "application/json");
  });
  // The solve's log from byte `from` on, whole lines only; X-Next-Offset says where to go on.
  server.Get("/api/log", [this](const httplib::Request& req, httplib::Response& res) {
    uint64_t from = 0;
    if (req.has_param("from")) {
      const std::string v = req.get_param_value("from");
      if (v.empty() || v.size() > 18 || !std::all_of(v.begin(), v.end(), ::isdigit)) {
        res.status = 400;
        return res.set_content("from: expected a byte offset", "text/plain");
      }
      from = std::stoull(v);
    }
    std::string text;
    std::ifstream in(o.workspace / "recon" / "log.jsonl", std::ios::binary);
    if (in) {
      in.seekg(0, std::ios::end);
      const uint64_t size = static_cast<uint64_t>(std::max<std::streamoff>(0, in.tellg()));
      if (from < size) {
        in.seekg(static_cast<std::streamoff>(from));
        text.resize(static_cast<size_t>(std::min<uint64_t>(size - from, 8u << 20)));
        in.read(text.data(), static_cast<std::streamsize>(text.size()));
        text.resize(static_cast<size_t>(in.gcount()));
        text.resize(text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1);
      }
    }
    res.set_header("Cache-Control", "no-store");
    res.set_header("X-Next-Offset", std::to_string(from + text.size()));
    res.set_content(text, "application/x-ndjson");
  });
  FieldRoutes();
  server.Get("/api/points", [this](const httplib::Request&, httplib::Response& res) {
    std::call_once(points_once, [this] { points = SparsePoints(o.workspace).dump(); });
    res.set_content(points, "application/json");
  });
  server.Get(R"(/files/(.+))", [this](const httplib::Request& req, httplib::Response& res) {
    const std::optional<fs::path> file = ServableFile(o.workspace, req.matches[1].str());
    if (!file) return NotFound(res, "file");
    const std::optional<std::string> bytes = ReadIfThere(*file);
    if (!bytes) return NotFound(res, "file");
    res.set_content(*bytes, ContentTypeOf(*file));
  });
  const auto refuse = [](const httplib::Request&, httplib::Response& res) {
    res.status = 405;
    res.set_content("perf view only reads", "text/plain");
  };
  // A Content-Length that is not a count of bytes is a malformed request, whatever the method
  // (httplib 0.11 answered some GETs carrying "-5" with the page).
  server.set_pre_routing_handler([](const httplib::Request& req, httplib::Response& res) {
    if (!req.has_header("Content-Length")) return httplib::Server::HandlerResponse::Unhandled;
    const std::string v = req.get_header_value("Content-Length");
    if (!v.empty() && v.size() <= 18 && v.find_first_not_of("0123456789") == std::string::npos) {
      return httplib::Server::HandlerResponse::Unhandled;
    }
    res.status = 400;
    res.set_content("bad Content-Length", "text/plain");
    return httplib::Server::HandlerResponse::Handled;
  });
  server.Post(R"(/.*)", refuse);
  server.Put(R"(/.*)", refuse);
  server.Delete(R"(/.*)", refuse);
  server.set_error_handler([](const httplib::Request&, httplib::Response& res) {
    if (res.body.empty()) res.set_content(std::to_string(res.status), "text/plain");
  });
  server.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr) {
    res.status = 500;
    res.set_content("internal error", "text/plain");
  });
}

// The fitted volume (field_source.h): /api/fields lists the levels and the live volume;
// /api/field?level=K (a level's checkpoint; none or "newest": the newest volume) sends one, gzip'd
// when the page takes it.
void ViewServer::Impl::FieldRoutes() {
  server.Get("/api/fields", [this](const httplib::Request&, httplib::Response& res) {
    res.set_header("Cache-Control", "no-store");
    res.set_content(fields->Listing().dump(), "application/json");
  });
  server.Get("/api/field", [this](const httplib::Request& req, httplib::Response& res) {
    int level = -1;
    if (req.has_param("level") && req.get_param_value("level") != "newest") {
      const std::string v = req.get_param_value("level");
      if (v.empty() || v.size() > 2 || !std::all_of(v.begin(), v.end(), ::isdigit)) {
        res.status = 400;
        return res.set_content("level: expected a level number or newest", "text/plain");
      }
      level = std::stoi(v);
    }
    std::optional<FieldSource::Response> r;
    try {
      r = fields->Payload(level, req.get_header_value("Accept-Encoding").find("gzip") != std::string::npos);
    } catch (const Error& e) {  // a damaged checkpoint: the page says so
      res.status = 422;
      return res.set_content(e.what(), "text/plain");
    }
    if (!r) return NotFound(res, level < 0 ? "volume (no level is finished yet)" : "volume of that level");
    res.set_header("Cache-Control", "no-store");
    if (r->gzip) res.set_header("Content-Encoding", "gzip");
    res.set_content(*r->bytes, "application/octet-stream");
  });
}

ViewServer::ViewServer(ViewOptions options) : impl_(std::make_unique<Impl>()) {
  impl_->o = std::move(options);
  impl_->fields = std::make_unique<FieldSource>(impl_->o.workspace);
  if (impl_->o.require_scene && !fs::is_regular_file(impl_->o.workspace / "scene.json")) {
    throw InputError(impl_->o.workspace.string(), "scene.json", "(missing)", "not a PERF workspace",
                     "run perf import (or perf run) first");
  }
  // SO_REUSEADDR only: httplib's default adds SO_REUSEPORT, with which a second perf view on a busy
  // port would bind too and share its requests with the first.
  impl_->server.set_socket_options([](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  });
  impl_->server.new_task_queue = [] { return new ConnectionThreads; };
  impl_->server.set_payload_max_length(kMaxPayload);
  impl_->server.set_read_timeout(5, 0);
  impl_->server.set_write_timeout(5, 0);
  impl_->Routes();
}

ViewServer::~ViewServer() { Stop(); }

int ViewServer::Bind() {
  Impl& m = *impl_;
  const bool ok = m.o.port == 0 ? (m.port = m.server.bind_to_any_port(m.o.host)) > 0
                                : m.server.bind_to_port(m.o.host, m.o.port) && (m.port = m.o.port) > 0;
  if (!ok) {
    throw IoError(StrCat(m.o.host, ":", m.o.port), "cannot listen there (in use, or not this machine's address)",
                  "pass another --port, or --port 0 for a free one");
  }
  return m.port;
}

void ViewServer::Serve() {
  impl_->serving = true;
  if (!impl_->stop_requested) impl_->server.listen_after_bind();
  impl_->serving = false;
}

void ViewServer::Stop() {
  if (!impl_) return;
  impl_->stop_requested = true;
  // Serve() may be between its check and the listening loop: wait until it listens or returns.
  while (impl_->serving && !impl_->server.is_running()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  impl_->server.stop();
}

std::string ViewServer::Url() const {
  const std::string host = impl_->o.host.find(':') != std::string::npos ? "[" + impl_->o.host + "]" : impl_->o.host;
  return StrCat("http://", host == "0.0.0.0" ? "127.0.0.1" : host, ":", impl_->port, "/");
}

void ViewServer::SetLiveStatus(std::function<nlohmann::json()> status) { impl_->live = std::move(status); }

void ViewServer::SetLiveField(std::function<std::shared_ptr<const LiveField>()> field) {
  impl_->fields->SetLive(std::move(field));
}

bool IsLoopback(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

}  // namespace perf::viewer
