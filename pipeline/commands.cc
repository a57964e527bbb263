// Options shared by several `perf` subcommands (commands.h).
#include "pipeline/commands.h"

#include <CLI/CLI.hpp>

namespace perf {

void AddDeviceOptions(CLI::App* cmd, std::string* device, int* threads) {
  cmd->add_option("--device", *device, "cpu, cuda or auto")->capture_default_str();
  cmd->add_option("-j,--threads", *threads, "CPU worker threads (0: all cores)")->capture_default_str();
}

void AddMinBoxOpacityOption(CLI::App* cmd, float* min_box_opacity, const std::string& use) {
  cmd->add_option("--min-box-opacity", *min_box_opacity,
                  use + ": rays whose box opacity is below this see only the shells (the paper's floater rule: "
                        "0.7; 0: off)")
      ->check(CLI::Range(0.0f, 1.0f))
      ->capture_default_str();
}

}  // namespace perf
