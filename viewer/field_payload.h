// The fitted volume as perf view's page draws it (viewer/page/field.js): one level's grid (dense,
// or its stored bricks with the brick table), its spherical harmonics and its shells, in half
// precision, with the box and shell placement, as one binary response of /api/field. The format is
// docs/viewer_field.md's (versioned; every section's size in the header, which the page checks
// against the counts before it allocates anything).
#pragma once

#include <cstdint>
#include <string>

#include "recon_cuda/data/checkpoint.h"

namespace perf::viewer {

inline constexpr uint32_t kFieldVersion = 1;
inline constexpr uint32_t kFieldHeaderBytes = 256;

// The payload of checkpoint `c`; `iteration`: the solver's iteration of a live volume (-1: a
// finished level's checkpoint). Throws InputError when the volume has more shells than the
// format holds.
std::string FieldPayload(const recon::Checkpoint& c, int iteration = -1);

// `bytes` as a gzip stream (zlib), for a client that accepts gzip.
std::string Gzip(const std::string& bytes);

}  // namespace perf::viewer
