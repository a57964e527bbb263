#include "pipeline/cli_run.h"

#include <CLI/CLI.hpp>
#include <cmath>
#include <csignal>
#include <iostream>
#include <new>
#include <string>
#include <string_view>

#include "common/comm.h"
#include "common/commit.h"
#include "common/version.h"
#include "common/errors.h"

namespace perf {
namespace {

// Whether this process is one of several ranks (mpirun).
bool SeveralRanks() { return LaunchedByMpi() && World().size() > 1; }

// Under mpirun with several ranks: "error (rank 1 of 4)", so that a user sees which rank failed.
std::string ErrorWord(const char* word) {
  if (!SeveralRanks()) return word;
  return StrCat(word, " (rank ", World().rank(), " of ", World().size(), ")");
}

// A rank that fails ends every rank of the job (MPI_Abort): the others would wait for it in their
// next sum for ever. A single process just exits with the code.
int End(int code) {
  if (SeveralRanks()) {
    std::cerr.flush();
    World().Abort(code);
  }
  return code;
}

// Every floating-point option of every subcommand refuses NaN (CLI11's ranges let it through, and a
// NaN passes every `<` check after them): exit 2 naming the option.
void RefuseNotANumber(CLI::App& app) {
  const CLI::Validator not_nan(
      [](std::string& v) -> std::string {
        double d = 0;
        return CLI::detail::lexical_cast(v, d) && std::isnan(d) ? StrCat(v, " is not a number") : std::string();
      },
      "");
  for (CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) {
    for (CLI::Option* option : sub->get_options()) {
      if (option->get_type_name().rfind("FLOAT", 0) == 0) option->check(not_nan);
    }
  }
}

}  // namespace

void AddVersionAndGuide(CLI::App& app, const char* program) {
  app.set_version_flag("--version", StrCat(program, " ", PERF_VERSION_STRING, " (commit ", PERF_COMMIT, ")"));
  app.footer("The guide: docs/ in PERF's source tree (docs/commands/ has a page per command; "
             "docs/troubleshooting.md explains every warning and error).");
}

int RunCommandLine(CLI::App& app, int argc, char** argv) {
  // Exit codes (docs/workspace.md "Exit codes"): 0 ok, 1 internal error (a bug), 2 bad input (a file, field or
  // option named in the message; also a workspace another perf command holds), 3 file system
  // (cannot read or write, disk full), 4 the work itself failed (e.g. the solver diverged),
  // 5 not enough memory, 130 stopped by Ctrl-C (resumable).
  // Under mpirun only reconstruct and run use ranks; every other command runs on rank 0 alone
  // (two ranks importing into one workspace would collide on its lock).
  if (argc > 1 && LaunchedByMpi()) {
    const std::string_view command = argv[1];
    if (command != "reconstruct" && command != "run" && !World().IsRoot()) return 0;
  }
  // A file size limit (ulimit -f) makes a too-large write fail (EFBIG, exit 3 naming the file)
  // instead of killing perf without a word.
  std::signal(SIGXFSZ, SIG_IGN);
  RefuseNotANumber(app);
  for (CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) {
    sub->footer(StrCat("Every option explained: docs/commands/", sub->get_name(),
                       ".md in PERF's source tree; warnings and errors: docs/troubleshooting.md"));
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version are ParseErrors that exit 0; every other one is bad input.
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const InputError& e) {
    std::cerr << ErrorWord("error") << ": " << e.what() << "\n";
    return End(2);
  } catch (const IoError& e) {
    std::cerr << ErrorWord("error") << ": " << e.what() << "\n";
    return End(3);
  } catch (const ResourceError& e) {
    std::cerr << ErrorWord("error") << ": " << e.what() << "\n";
    return End(5);
  } catch (const Interrupted& e) {
    std::cerr << ErrorWord("stopped") << ": " << e.what() << "\n";
    return End(130);
  } catch (const InternalError& e) {
    std::cerr << ErrorWord("error") << ": " << e.what()
              << "\nThis is a bug in perf; please report it with the command line.\n";
    return End(1);
  } catch (const std::bad_alloc&) {
    std::cerr << ErrorWord("error")
              << ": out of memory; use a smaller --max-size or --downscale, fewer --levels, or fewer threads (-j)\n";
    return End(5);
  } catch (const std::exception& e) {
    std::cerr << ErrorWord("error") << ": " << e.what() << "\n";
    return End(4);
  }
  return 0;
}

}  // namespace perf
