// NCCL between the GPUs of the ranks: one GPU per rank, the communicator bootstrapped
// over the host one (MPI: rank 0's ncclUniqueId reaches the others as a sum). Vectors in device
// memory are summed where they lie (ncclAllReduce, ring or tree: every rank receives the same
// bits); scalars and host vectors go through the host communicator. Built when the CUDA toolkit
// ships NCCL (PERF_WITH_NCCL); only the perf executable links it.
#pragma once

#include <memory>

#include "common/comm.h"

namespace perf::recon {

// On the current CUDA device (the rank's, set by its CUDA backend). `host` must outlive it.
// Throws Error naming NCCL's message when the communicator cannot be made.
std::unique_ptr<Communicator> MakeNcclCommunicator(Communicator& host);

}  // namespace perf::recon
