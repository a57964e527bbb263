// World() apart from comm.cc, so that only what launches ranks (the perf executable) links MPI;
// the GPU benchmark links the rest of perf_comm without it.
#include "common/comm.h"

#ifdef PERF_WITH_MPI
#include "common/mpi_comm.h"
#endif

namespace perf {

Communicator& World() {
#ifdef PERF_WITH_MPI
  if (LaunchedByMpi()) return MpiWorld();
#endif
  static SingleProcess single;
  return single;
}

}  // namespace perf
