// `perf view WORKSPACE`: serves the workspace's page (viewer/view_server.h) until Ctrl-C.
#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <iostream>
#include <thread>

#include "common/errors.h"
#include "pipeline/commands.h"
#include "viewer/view_server.h"

namespace perf {

void AddViewCommand(CLI::App& app) {
  auto o = std::make_shared<viewer::ViewOptions>();
  CLI::App* cmd = app.add_subcommand(
      "view",
      "Serve a page that shows the workspace (box, shells, cameras with their photos, mesh, sparse points, "
      "held-out views with their scores, masks, the PSNR curve) on a local port; works offline and over ssh -L.");
  cmd->add_option("workspace", o->workspace, "Workspace folder")->required();
  cmd->add_option("--port", o->port, "Port to listen on (0: a free one)")->check(CLI::Range(0, 65535))->capture_default_str();
  cmd->add_option("--host", o->host,
                  "Address to listen on; anything but 127.0.0.1 lets other machines read the workspace's photos")
      ->capture_default_str();
  cmd->callback([o]() {
    viewer::ViewServer server(*o);
    const int port = server.Bind();
    if (!viewer::IsLoopback(o->host)) {
      std::cerr << "perf view: warning: listening on " << o->host << ":" << port
                << ": anyone who can reach this machine there can read the workspace's photos and results; "
                   "127.0.0.1 with ssh -L is the safe way to look from elsewhere\n";
    }
    std::cout << "perf view: " << o->workspace.string() << " at " << server.Url() << " (Ctrl-C stops)\n"
              << "  from another machine: ssh -L " << port << ":127.0.0.1:" << port
              << " THIS_HOST, then open http://127.0.0.1:" << port << "/\n"
              << std::flush;
    StopOnCtrlC ctrl_c;
    std::atomic<bool> served{false};
    std::thread watcher([&server, &served] {
      while (!StopRequested().load() && !served.load()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
      server.Stop();
    });
    server.Serve();
    served.store(true);
    watcher.join();
    std::cout << "perf view: stopped\n";
  });
}

}  // namespace perf
