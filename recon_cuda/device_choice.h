// The choices a command line makes about the reconstruction, as types (the CLI maps the words).
#pragma once

namespace perf::recon {

// Which backend a command runs on (--device): kAuto is CUDA when a device is visible, else the CPU.
enum class DeviceChoice { kAuto, kCpu, kCuda };

// The shells (--background): learn them (the paper), or keep them fixed at scene.json's
// background, the colour RGBA photos were composited over on import; kAuto is fixed when every
// photo had an alpha channel (e.g. NeRF synthetic), learned otherwise.
enum class BackgroundChoice { kAuto, kFixed, kLearn };

// Per-photo exposure (--exposure, issue 16): solve each training photo's gain and offset per
// channel with the volume, or not; kAuto solves them for photos from COLMAP (real captures) and
// not for NeRF json scenes (synthetic renders share one exposure).
enum class ExposureChoice { kAuto, kOn, kOff };

// Which of a workspace's photos a command renders or scores (--split).
enum class ViewSplit { kTest, kTrain, kAll };

}  // namespace perf::recon
