// Block-Jacobi preconditioning of the photos' pose corrections (pose.h): a photo's 7 pose values
// are coupled through every one of its rays (a rotation and a sideways shift move its pixels
// alike), so the Jacobi preconditioner's diagonal leaves CG to find their correlations one
// iteration at a time; the exact 7 x 7 block of J^T J per photo, inverted, gives the pose part of
// each CG step the Gauss-Newton step of the photo alone. The volume keeps the diagonal.
#pragma once

#include <cstdint>
#include <span>

namespace perf::recon {

// For each of `photos` pose groups of 8 values (r, diag, free, z: the pose part of their vectors,
// PoseParam order): z = B^-1 r over the free values, 0 on the held ones, B the photo's block of
// `blocks` (kPoseBlock values, J^T J of the data) with its diagonal replaced by max(diag, floor)
// (diag: the system's diagonal, priors included). A block that is not positive definite (a photo
// without rays) leaves z = r / max(diag, floor).
void SolvePoseBlocks(int photos, std::span<const double> blocks, const float* r, const float* diag, const float* free,
                     float floor, float* z);

}  // namespace perf::recon
