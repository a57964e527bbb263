// perf_gpu: perf's reconstruct and render subcommands alone, built to run on a bare GPU machine
// (CUDA driver, glibc 2.35, none of Debian's libraries): it links no OpenImageIO, OpenCV, OpenVDB,
// MPI or viewer, reads and writes the workspace's PNG images through libpng (workspace/png_io.h),
// and downscales its image pyramid by area averaging (workspace/image_ops.h). A workspace imported
// by perf here is fitted there and comes back for perf export, eval and view
// (bench/README.md "perf on a GPU machine").
#include <CLI/CLI.hpp>
#include <string>

#include "pipeline/cli_run.h"
#include "pipeline/commands.h"

int main(int argc, char** argv) {
  CLI::App app{
      "perf_gpu: perf reconstruct and perf render for a machine with a GPU and none of perf's libraries. Import "
      "with perf first; export, eval and view the workspace with perf.",
      "perf_gpu"};
  perf::AddVersionAndGuide(app, "perf_gpu");
  app.require_subcommand(1);
  perf::AddReconstructCommand(app);
  perf::AddRenderCommand(app);
  return perf::RunCommandLine(app, argc, argv);
}
