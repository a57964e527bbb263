// The placement range every reader accepts (scene.json, checkpoints): a box side from a
// micrometre in metres to a million km, and every position and radius within that span of the
// origin; beyond it the exports' transforms overflow or vanish.
#pragma once

namespace perf {

inline constexpr double kMinBoxSide = 1e-6, kMaxWorldSpan = 1e9;

}  // namespace perf
