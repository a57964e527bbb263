// A quick visual check of the box placement: the 12 box edges drawn in red over workspace
// images, so a user can see at a glance that the box holds the object.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <vector>

#include "workspace/image.h"
#include "workspace/scene.h"

namespace perf {

// Pixel positions (PERF convention) of the box's 8 corners in image `index`; a corner behind the
// camera gets NaN.
std::vector<Eigen::Vector2d> ProjectBoxCorners(const Scene& scene, size_t index);

// Draws the box edges into `image` (the workspace image of `scene.images[index]`).
void DrawBox(const Scene& scene, size_t index, Image* image);

// Writes WORKSPACE/preview/box_<name>.png for the held-out images (or the first few if there
// are none); returns the paths written.
std::vector<std::filesystem::path> WriteBoxPreviews(const Scene& scene,
                                                    const std::filesystem::path& workspace,
                                                    int max_images = 8);

}  // namespace perf
