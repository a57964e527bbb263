// The `perf` command line: one executable, one subcommand per stage (DESIGN.md "Stages").
#include <CLI/CLI.hpp>
#include <csignal>
#include <iostream>
#include <new>
#include <string_view>

#include "common/comm.h"
#include "common/errors.h"
#include "common/version.h"
#include "pipeline/commands.h"

namespace {

// Whether this process is one of several ranks (mpirun).
bool SeveralRanks() { return perf::LaunchedByMpi() && perf::World().size() > 1; }

// Under mpirun with several ranks: "error (rank 1 of 4)", so that a user sees which rank failed.
std::string ErrorWord(const char* word) {
  if (!SeveralRanks()) return word;
  return perf::StrCat(word, " (rank ", perf::World().rank(), " of ", perf::World().size(), ")");
}

// A rank that fails ends every rank of the job (MPI_Abort): the others would wait for it in their
// next sum for ever. A single process just exits with the code.
int End(int code) {
  if (SeveralRanks()) {
    std::cerr.flush();
    perf::World().Abort(code);
  }
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "PERF: Performant, Explicit Radiance Fields. Photos or a COLMAP model in; a radiance field, "
      "foreground masks and DCC assets out.",
      "perf"};
  app.set_version_flag("--version", std::string("perf ") + PERF_VERSION_STRING);
  app.require_subcommand(1);
  perf::AddSfmCommand(app);
  perf::AddImportCommand(app);
  perf::AddReconstructCommand(app);
  perf::AddRenderCommand(app);
  perf::AddExportCommand(app);
  perf::AddEvalCommand(app);
  perf::AddRunCommand(app);
  perf::AddViewCommand(app);
  perf::RefuseNotANumber(app);
  // Exit codes (README "Safety"): 0 ok, 1 internal error (a bug), 2 bad input (a file, field or
  // option named in the message; also a workspace another perf command holds), 3 file system
  // (cannot read or write, disk full), 4 the work itself failed (e.g. the solver diverged),
  // 5 not enough memory, 130 stopped by Ctrl-C (resumable).
  // Under mpirun only reconstruct and run use ranks; every other command runs on rank 0 alone
  // (two ranks importing into one workspace would collide on its lock).
  if (argc > 1 && perf::LaunchedByMpi()) {
    const std::string_view command = argv[1];
    if (command != "reconstruct" && command != "run" && !perf::World().IsRoot()) return 0;
  }
  // A file size limit (ulimit -f) makes a too-large write fail (EFBIG, exit 3 naming the file)
  // instead of killing perf without a word.
  std::signal(SIGXFSZ, SIG_IGN);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version are ParseErrors that exit 0; every other one is bad input.
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const perf::InputError& e) {
    std::cerr << ErrorWord("error") << ": " << e.what() << "\n";
    return End(2);
  } catch (const perf::IoError& e) {
    std::cerr << ErrorWord("error") << ": " << e.what() << "\n";
    return End(3);
  } catch (const perf::ResourceError& e) {
    std::cerr << ErrorWord("error") << ": " << e.what() << "\n";
    return End(5);
  } catch (const perf::Interrupted& e) {
    std::cerr << ErrorWord("stopped") << ": " << e.what() << "\n";
    return End(130);
  } catch (const perf::InternalError& e) {
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
