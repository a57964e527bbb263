// --view for the commands that serve perf view's page while they run (perf only: perf_gpu has no
// viewer, commands.h).
#include <CLI/CLI.hpp>
#include <iostream>

#include "common/errors.h"
#include "pipeline/commands.h"
#include "viewer/live_view.h"

namespace perf {

void AddLiveViewOptions(CLI::App* cmd, bool* view, int* port, std::string* image, const std::string& after) {
  cmd->add_flag("--view", *view,
                StrCat("Serve perf view's page while the command runs (stage, iteration, ETA, the PSNR curve, a photo's "
                       "view rendered each iteration); ", after));
  cmd->add_option("--view-port", *port, "With --view: the page's port (0: a free one)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  cmd->add_option("--view-image", *image,
                  "The photo rendered after each iteration for the page (its name in the capture; default: the first "
                  "held-out one)");
}

std::unique_ptr<viewer::LiveView> StartLiveView(bool view, bool root, viewer::ViewOptions options,
                                                const std::filesystem::path& workspace, const std::string& command) {
  if (!view || !root) return nullptr;
  options.workspace = workspace;
  auto live = std::make_unique<viewer::LiveView>(options);
  live->Stage(command);
  std::cout << "perf " << command << ": its page is at " << live->Url() << " (from another machine: ssh -L "
            << live->port() << ":127.0.0.1:" << live->port() << " THIS_HOST)\n"
            << std::flush;
  return live;
}

}  // namespace perf
