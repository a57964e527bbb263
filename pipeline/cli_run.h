// What perf's and perf_gpu's main() share: parsing the command line and running its subcommand,
// every error turned into its message and exit code (docs/workspace.md "Exit codes"), a failing rank ending
// every rank of an MPI job.
#pragma once

namespace CLI {
class App;
}

namespace perf {

// --version prints "<program> <version> (commit <git commit>)"; every subcommand's --help ends with
// the page of the guide that documents it (docs/commands/<name>.md). Call before adding commands.
void AddVersionAndGuide(CLI::App& app, const char* program);

// Parses argv into `app` (its subcommands added) and runs the chosen one; returns the exit code.
int RunCommandLine(CLI::App& app, int argc, char** argv);

}  // namespace perf
