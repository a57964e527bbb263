// The `perf` subcommands. Each Add*Command registers its options and a callback on `app`;
// errors propagate as perf::Error and are turned into messages and exit codes by main().
#pragma once

#include <string>

namespace CLI {
class App;
}

namespace perf {

void AddImportCommand(CLI::App& app);
void AddSfmCommand(CLI::App& app);
void AddReconstructCommand(CLI::App& app);
void AddRenderCommand(CLI::App& app);
void AddExportCommand(CLI::App& app);
void AddEvalCommand(CLI::App& app);
void AddRunCommand(CLI::App& app);

// --device and -j,--threads: the same for every command that runs a backend.
void AddDeviceOptions(CLI::App* cmd, std::string* device, int* threads);

// --min-box-opacity: the render rule (recon_cuda/render_rule.h) for what `use` names.
void AddMinBoxOpacityOption(CLI::App* cmd, float* min_box_opacity, const std::string& use);

}  // namespace perf
