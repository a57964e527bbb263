// libFuzzer target for the COLMAP model readers (sfm_import/colmap_model.h). Every input must
// either read or throw perf::Error; anything else (another exception, a crash, a leak,
// undefined behaviour, a hang, an allocation out of proportion to the input) is a bug.
// Build, seed and run with scripts/fuzz.sh.
//
// Each input is used three ways:
//  - whole, by each binary reader, so real cameras.bin / images.bin / points3D.bin files are
//    useful seeds; a file that reads must write and read back to the same bytes;
//  - as a whole model, [uint32 cameras size][uint32 images size][cameras][images][points3D]
//    (little-endian sizes), read into one Reconstruction and validated, so that
//    ValidateReconstruction sees models whose parts parse;
//  - whole, by each text reader (cheap, and the same robustness promise holds for them).
//
// Built with -DPERF_FUZZ_MAKE_SEEDS instead, this file is a small program that writes seed
// inputs (a hand-built model with every camera model, and a cut-down bonsai model when given).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <string_view>

#include "common/errors.h"
#include "sfm_import/colmap_model.h"

namespace {

using perf::colmap::Reconstruction;
using Reader = void (*)(std::istream&, const std::string&, Reconstruction*);
using Writer = void (*)(std::ostream&, const Reconstruction&);

struct BinaryFile {
  Reader read;
  Writer write;
};
constexpr BinaryFile kBinary[] = {
    {perf::colmap::ReadCamerasBinary, perf::colmap::WriteCamerasBinary},
    {perf::colmap::ReadImagesBinary, perf::colmap::WriteImagesBinary},
    {perf::colmap::ReadPoints3DBinary, perf::colmap::WritePoints3DBinary},
};
constexpr Reader kText[] = {perf::colmap::ReadCamerasText, perf::colmap::ReadImagesText,
                            perf::colmap::ReadPoints3DText};

std::string Write(Writer write, const Reconstruction& rec) {
  std::ostringstream out;
  write(out, rec);
  return out.str();
}

// True if `bytes` read; throws only perf::Error, which the caller treats as a rejection.
bool Read(Reader read, std::string_view bytes, Reconstruction* rec) {
  std::istringstream in{std::string(bytes)};
  try {
    read(in, "fuzz", rec);
    return true;
  } catch (const perf::Error&) {
    return false;
  }
}

void Validate(const Reconstruction& rec) {
  try {
    perf::colmap::ValidateReconstruction(rec, "fuzz");
  } catch (const perf::Error&) {
  }
}

uint32_t U32(const uint8_t* p) {
  return uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
}

}  // namespace

#ifndef PERF_FUZZ_MAKE_SEEDS

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);

  for (const BinaryFile& file : kBinary) {
    Reconstruction rec;
    if (!Read(file.read, bytes, &rec)) continue;
    // What reads must be writable, and rewriting it must be stable (a reader/writer mismatch
    // would corrupt models that PERF passes on). No try here: any exception is a finding.
    const std::string once = Write(file.write, rec);
    Reconstruction again;
    std::istringstream in(once);
    file.read(in, "rewritten", &again);
    if (Write(file.write, again) != once) {
      std::fprintf(stderr, "binary rewrite is not stable\n");
      std::abort();
    }
    Validate(rec);
  }

  if (size >= 8) {
    const uint64_t cameras = U32(data), images = U32(data + 4);
    if (cameras + images <= size - 8) {
      Reconstruction rec;
      Read(kBinary[0].read, bytes.substr(8, cameras), &rec);
      Read(kBinary[1].read, bytes.substr(8 + cameras, images), &rec);
      Read(kBinary[2].read, bytes.substr(8 + cameras + images), &rec);
      Validate(rec);
    }
  }

  Reconstruction text;
  for (const Reader read : kText) Read(read, bytes, &text);
  Validate(text);
  return 0;
}

#else  // PERF_FUZZ_MAKE_SEEDS

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "sfm_import/camera_models.h"

namespace {

namespace fs = std::filesystem;
using namespace perf::colmap;

void Save(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// Seeds for one model: each binary file, the whole-model layout, and the text files.
void SaveModel(const fs::path& dir, const std::string& prefix, const Reconstruction& rec) {
  const std::string cameras = Write(WriteCamerasBinary, rec),
                    images = Write(WriteImagesBinary, rec);
  const std::string points = Write(WritePoints3DBinary, rec);
  Save(dir / (prefix + ".cameras.bin"), cameras);
  Save(dir / (prefix + ".images.bin"), images);
  Save(dir / (prefix + ".points3D.bin"), points);
  std::string model(8, '\0');
  for (int i = 0; i < 4; ++i) {
    model[i] = static_cast<char>(cameras.size() >> (8 * i));
    model[4 + i] = static_cast<char>(images.size() >> (8 * i));
  }
  Save(dir / (prefix + ".model"), model + cameras + images + points);
  Save(dir / (prefix + ".cameras.txt"), Write(WriteCamerasText, rec));
  Save(dir / (prefix + ".images.txt"), Write(WriteImagesText, rec));
  Save(dir / (prefix + ".points3D.txt"), Write(WritePoints3DText, rec));
}

// A valid model with one camera of every COLMAP model, as in tests/sfm_import.
Reconstruction SmallModel() {
  Reconstruction rec;
  for (int id = 0; id < 12; ++id) {
    Camera& cam = rec.cameras[static_cast<uint32_t>(id + 1)];
    cam.camera_id = static_cast<uint32_t>(id + 1);
    cam.model_id = id;
    cam.width = 640;
    cam.height = 480;
    cam.params.assign(static_cast<size_t>(FindCameraModel(id)->num_params), 0.01);
    cam.params[0] = 500;
  }
  for (uint32_t id : {1u, 9u}) {
    Image& image = rec.images[id];
    image.image_id = id;
    image.camera_id = id;
    image.name = id == 1 ? "a.jpg" : "dir/b c.png";
    image.points2D = {{1.5, 2.5, 0}, {3, 4, kInvalidPoint3DId}};
  }
  rec.points3D[0] = Point3D{0, {1, 2, 3}, {10, 20, 30}, 0.5, {{1, 0}, {9, 0}}};
  return rec;
}

// The first few bonsai images with a few points each, and the points seen in them.
Reconstruction CutDown(const Reconstruction& full) {
  Reconstruction rec;
  rec.cameras = full.cameras;
  for (const auto& [id, image] : full.images) {
    if (rec.images.size() == 3) break;
    Image& cut = rec.images[id] = image;
    cut.points2D.resize(std::min<size_t>(cut.points2D.size(), 40));
  }
  for (const auto& [id, point] : full.points3D) {
    Point3D cut = point;
    std::erase_if(cut.track, [&](const TrackElement& t) {
      const auto image = rec.images.find(t.image_id);
      return image == rec.images.end() || t.point2D_idx >= image->second.points2D.size();
    });
    if (!cut.track.empty() && rec.points3D.size() < 30) rec.points3D[id] = cut;
  }
  return rec;
}

}  // namespace

// Usage: make_seeds OUT_DIR [BONSAI_MODEL_DIR]
int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: " << argv[0] << " OUT_DIR [COLMAP_MODEL_DIR]\n";
    return 2;
  }
  const fs::path out = argv[1];
  fs::create_directories(out);
  SaveModel(out, "small", SmallModel());
  if (argc > 2 && fs::is_directory(argv[2])) {
    try {
      SaveModel(out, "bonsai", CutDown(ReadReconstruction(argv[2])));
      std::ifstream raw(fs::path(argv[2]) / "cameras.bin", std::ios::binary);
      std::ostringstream bytes;
      bytes << raw.rdbuf();
      Save(out / "bonsai_raw.cameras.bin", bytes.str());
    } catch (const perf::Error& e) {
      std::cerr << "no bonsai seeds: " << e.what() << "\n";
    }
  }
  return 0;
}

#endif  // PERF_FUZZ_MAKE_SEEDS
