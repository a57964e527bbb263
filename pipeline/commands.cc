// Options shared by several `perf` subcommands (commands.h).
#include "pipeline/commands.h"

#include <CLI/CLI.hpp>

namespace perf {

void AddDeviceOptions(CLI::App* cmd, std::string* device, int* threads) {
  cmd->add_option("--device", *device, "cpu, cuda or auto")->capture_default_str();
  cmd->add_option("-j,--threads", *threads, "CPU worker threads (0: all cores)")->capture_default_str();
}

}  // namespace perf
