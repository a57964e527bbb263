// The `perf` command line: one executable, one subcommand per stage (DESIGN.md "Stages").
#include <CLI/CLI.hpp>
#include <string>

#include "pipeline/cli_run.h"
#include "pipeline/commands.h"

int main(int argc, char** argv) {
  CLI::App app{
      "PERF: Performant, Explicit Radiance Fields. Photos or a COLMAP model in; a radiance field, "
      "foreground masks and DCC assets out.",
      "perf"};
  perf::AddVersionAndGuide(app, "perf");
  app.require_subcommand(1);
  perf::AddSfmCommand(app);
  perf::AddImportCommand(app);
  perf::AddReconstructCommand(app);
  perf::AddRenderCommand(app);
  perf::AddExportCommand(app);
  perf::AddEvalCommand(app);
  perf::AddRunCommand(app);
  perf::AddViewCommand(app);
  return perf::RunCommandLine(app, argc, argv);
}
