// MPI's world as a Communicator (comm.h); built with PERF_WITH_MPI only. MPI is initialised on
// the first call and finalised at exit; ranks sum with MPI_Reduce to rank 0 and MPI_Bcast, so
// the order of every sum is fixed for a given number of ranks and all ranks get the same bits
// (MPI_Allreduce promises neither).
#pragma once

#include "common/comm.h"

namespace perf {

Communicator& MpiWorld();

}  // namespace perf
