// Rewrites a COLMAP model keeping only the 2D points that observe a 3D point (tracks are
// re-indexed), which shrinks images.bin ~20x. Used once to make this example; see README.md.
// Build: g++ -std=c++20 -I. examples/bonsai_mini/strip_model.cc sfm_import/colmap_model.cc \
//          sfm_import/camera_models.cc common/errors.cc common/atomic_file.cc -o strip_model
#include <iostream>
#include <map>

#include "sfm_import/colmap_model.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: strip_model IN_DIR OUT_DIR\n";
    return 2;
  }
  using namespace perf::colmap;
  Reconstruction rec = ReadReconstruction(argv[1]);
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> new_index;
  for (auto& [id, im] : rec.images) {
    std::vector<Point2D> kept;
    for (uint32_t i = 0; i < im.points2D.size(); ++i) {
      if (im.points2D[i].point3D_id == kInvalidPoint3DId) continue;
      new_index[{id, i}] = static_cast<uint32_t>(kept.size());
      kept.push_back(im.points2D[i]);
    }
    im.points2D = std::move(kept);
  }
  for (auto& [id, p] : rec.points3D) {
    for (auto& t : p.track) t.point2D_idx = new_index.at({t.image_id, t.point2D_idx});
  }
  WriteReconstruction(argv[2], rec, ModelFormat::kBinary);
  return 0;
}
