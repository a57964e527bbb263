// `perf view`: one page over a workspace, served on a local port (cpp-httplib), that shows the
// fitted volume from any viewpoint (field_source.h), the box, the shells, every camera with its
// photo, the mesh and the sparse points, the held-out views
// next to their photos, masks and cut-outs with their scores, the PSNR curve and the stage times.
// The server only reads the workspace, answers a fixed set of routes (viewer/view_files.h for the
// files) and holds no lock: a solve writing the workspace is never blocked by it.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json_fwd.hpp>
#include <string>

namespace perf::viewer {

struct LiveField;

struct ViewOptions {
  std::filesystem::path workspace;
  std::string host = "127.0.0.1";
  int port = 8765;  // 0: a free port the system picks
  // Where Debian's libjs-three put three.js (build/three.min.js and examples/js/...).
  std::filesystem::path three_dir = PERF_THREE_DIR;
  // The workspace must have its scene.json already (perf view); a live page (perf run --view)
  // starts before the import writes it and shows it once it is there.
  bool require_scene = true;
};

class ViewServer {
 public:
  explicit ViewServer(ViewOptions options);
  ~ViewServer();
  ViewServer(const ViewServer&) = delete;
  ViewServer& operator=(const ViewServer&) = delete;

  // Binds host:port (throws IoError naming them when it cannot); returns the port bound.
  int Bind();
  // Serves until Stop() (from another thread); returns when the last request is answered.
  void Serve();
  void Stop();
  // "http://127.0.0.1:8765/"
  std::string Url() const;
  // A running command's state for /api/status (live_view.h): a JSON object merged into the
  // status; called from the server's threads.
  void SetLiveStatus(std::function<nlohmann::json()> status);
  // A running command's newest volume for /api/field (field_source.h); called from the server's
  // threads.
  void SetLiveField(std::function<std::shared_ptr<const LiveField>()> field);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Whether `host` is only reachable from this machine (127.0.0.0/8, ::1, localhost).
bool IsLoopback(const std::string& host);

}  // namespace perf::viewer
