#include "recon_cuda/solve/backend.h"

#include <vector>

namespace perf::recon {

void Backend::SumAcrossRanks(VecId v, Communicator& comm) {
  if (comm.size() == 1) return;
  std::vector<float> host(static_cast<size_t>(level().shape.ParamCount()));
  Download(v, host);
  comm.SumInPlace(host);
  Upload(v, host);
}

}  // namespace perf::recon
