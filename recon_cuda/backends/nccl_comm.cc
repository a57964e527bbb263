#include "recon_cuda/backends/nccl_comm.h"

#include <cuda_runtime.h>
#include <nccl.h>

#include <cstring>
#include <vector>

#include "common/errors.h"

namespace perf::recon {
namespace {

void CheckNccl(ncclResult_t r, const char* what) {
  if (r != ncclSuccess) throw Error(StrCat("NCCL ", what, " failed: ", ncclGetErrorString(r)));
}

class NcclCommunicator final : public Communicator {
 public:
  explicit NcclCommunicator(Communicator& host) : host_(host) {
    ncclUniqueId id;
    std::memset(&id, 0, sizeof(id));
    if (host.IsRoot()) CheckNccl(ncclGetUniqueId(&id), "ncclGetUniqueId");
    // Broadcast as a sum: every other rank contributes zeros (bytes are exact in doubles).
    std::vector<double> bytes(sizeof(id));
    for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<unsigned char>(id.internal[i]);
    host.SumInPlace(bytes);
    for (size_t i = 0; i < bytes.size(); ++i) id.internal[i] = static_cast<char>(static_cast<unsigned char>(bytes[i]));
    CheckNccl(ncclCommInitRank(&comm_, host.size(), id, host.rank()), "ncclCommInitRank");
  }
  ~NcclCommunicator() override { ncclCommDestroy(comm_); }

  int rank() const override { return host_.rank(); }
  int size() const override { return host_.size(); }
  std::string Describe() const override { return StrCat(host_.Describe(), " + NCCL"); }
  void SumInPlace(std::span<float> v) override { host_.SumInPlace(v); }
  void SumInPlace(std::span<double> v) override { host_.SumInPlace(v); }
  void MaxInPlace(std::span<double> v) override { host_.MaxInPlace(v); }
  // On the legacy default stream, after every kernel the backend queued there.
  bool SumDeviceInPlace(float* values, size_t n) override {
    CheckNccl(ncclAllReduce(values, values, n, ncclFloat, ncclSum, comm_, cudaStreamLegacy), "ncclAllReduce");
    const cudaError_t e = cudaStreamSynchronize(cudaStreamLegacy);
    if (e != cudaSuccess) throw Error(StrCat("NCCL sum: ", cudaGetErrorString(e)));
    return true;
  }
  void Barrier() override { host_.Barrier(); }
  void Abort(int code) override {
    ncclCommAbort(comm_);
    host_.Abort(code);
  }

 private:
  Communicator& host_;
  ncclComm_t comm_ = nullptr;
};

}  // namespace

std::unique_ptr<Communicator> MakeNcclCommunicator(Communicator& host) {
  return std::make_unique<NcclCommunicator>(host);
}

}  // namespace perf::recon
