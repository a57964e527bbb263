// The render rule (paper "Rendering"): where the box's opacity along a ray, 1 - T_box, is below a
// threshold, the box is treated as empty and the ray sees only the shells, hiding faint floaters.
#pragma once

namespace perf::recon {

// The paper's threshold; `--min-box-opacity 0.7` applies it.
inline constexpr float kPaperMinBoxOpacity = 0.7f;

// PERF renders, previews and scores the volume as fitted (rule off) by default. The rule also
// clears every partly covered pixel along the object's silhouette and its thin parts, which costs
// held-out PSNR, while the floaters it hides are faint once the opacity residual fits the photos'
// alpha (docs/tuning.md "Background").
inline constexpr float kDefaultMinBoxOpacity = 0.0f;

}  // namespace perf::recon
