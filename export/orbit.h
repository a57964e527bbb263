// An orbit of cameras around the reconstruction box, for turntable renders: on a circle about
// the box's up axis (scene.json's box z, turned upright on import), at the median distance of
// the photos' cameras from the box centre, looking at the centre, with the median photo's
// field of view. Where the photos cover less of the circle (a frontal capture), the orbit sweeps
// the arc they cover and back instead of showing the unseen side.
#pragma once

#include <vector>

#include "recon_cuda/core/ray_math.h"
#include "workspace/scene.h"

namespace perf::exporter {

struct OrbitOptions {
  int frames = 60;
  double elevation_degrees = 20;  // above the box's horizontal plane
  int width = 0, height = 0;      // 0: the first camera's workspace size
  bool follow_capture = true;     // sweep the captured arc where the photos leave a gap (CapturedArc)
};

// The part of the circle about the box's up axis that the photos (not those left out) see from:
// start and span in radians, azimuth in the box frame. A full turn (span 2 pi) when no gap
// between neighbouring photos exceeds kMaxOrbitGap; else the covered arc, widened to at least
// kMinOrbitArc.
struct Arc {
  double start = 0, span = 0;
};
inline constexpr double kMaxOrbitGap = 2.0944;   // 120 degrees
inline constexpr double kMinOrbitArc = 1.0472;   // 60 degrees
Arc CapturedArc(const Scene& scene);

struct OrbitView {
  recon::PinholeCamera<float> camera;
  int width = 0, height = 0;
};

// One turn at 0.1 degree a frame; more is surely a typo.
inline constexpr int kMaxOrbitFrames = 3600;

// Throws InputError naming the option for frames outside 1..kMaxOrbitFrames or an elevation
// outside (-89, 89) degrees.
void CheckOrbitOptions(const OrbitOptions& options);

// Throws as CheckOrbitOptions, and InputError for a scene without images.
std::vector<OrbitView> OrbitCameras(const Scene& scene, const OrbitOptions& options);

}  // namespace perf::exporter
