// What perf's and perf_gpu's main() share: parsing the command line and running its subcommand,
// every error turned into its message and exit code (README "Safety"), a failing rank ending
// every rank of an MPI job.
#pragma once

namespace CLI {
class App;
}

namespace perf {

// Parses argv into `app` (its subcommands added) and runs the chosen one; returns the exit code.
int RunCommandLine(CLI::App& app, int argc, char** argv);

}  // namespace perf
