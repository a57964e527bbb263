#include "sfm_import/sfm_models.h"

#include <cstdint>
#include <fstream>
#include <set>
#include <system_error>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/owned_files.h"
#include "sfm_import/colmap_model.h"

namespace fs = std::filesystem;

namespace perf::sfm_detail {
namespace {

// The record count at the start of a COLMAP binary file (uint64, little-endian). Reading only
// the header keeps model selection independent of the full reader and cheap for big models.
std::optional<uint64_t> ReadBinaryCount(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char bytes[8];
  if (!in.read(reinterpret_cast<char*>(bytes), sizeof bytes)) return std::nullopt;
  uint64_t n = 0;
  for (int i = 7; i >= 0; --i) n = (n << 8) | bytes[i];
  return n;
}

// The photos a model holds (COLMAP image names); nullopt when it cannot be read in full.
std::optional<std::set<std::string>> RegisteredNames(const fs::path& dir) {
  try {
    std::set<std::string> names;
    for (const auto& [id, im] : colmap::ReadReconstruction(dir).images) names.insert(im.name);
    return names;
  } catch (const Error&) {
    return std::nullopt;
  }
}

}  // namespace

std::optional<ModelCounts> ReadModelCounts(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_regular_file(dir / "cameras.bin", ec)) return std::nullopt;
  const auto images = ReadBinaryCount(dir / "images.bin");
  const auto points = ReadBinaryCount(dir / "points3D.bin");
  // Counts beyond int range can only come from a garbled file.
  if (!images || !points || *images > INT32_MAX || *points > INT32_MAX) return std::nullopt;
  return ModelCounts{static_cast<int>(*images), static_cast<int>(*points)};
}

std::optional<std::vector<std::string>> LeftOut(const std::vector<std::string>& inputs, const fs::path& dir) {
  const auto registered = RegisteredNames(dir);
  if (!registered) return std::nullopt;
  std::vector<std::string> out;
  for (const std::string& name : inputs) {
    if (!registered->count(name)) out.push_back(name);
  }
  return out;
}

void ReplaceDirectory(const fs::path& src, const fs::path& dst) {
  EnsureWritableDirectory(dst.parent_path());
  CheckReplaceable(dst, "replacing the sparse model");  // before any copying
  const fs::path tmp = TempPathFor(dst);
  const fs::path old = TempPathFor(dst.string() + ".old");
  std::error_code ec;
  if (!fs::create_directory(tmp, ec)) {
    throw IoError(dst.string(), "cannot create a folder beside it: " + (ec ? ec.message() : "it exists"),
                  "check that the workspace is writable");
  }
  RecordTemporary(tmp);  // the sweep removes it if this process is killed
  fs::copy(src, tmp, fs::copy_options::recursive, ec);
  if (ec) {
    fs::remove_all(tmp, ec);
    throw IoError(dst.string(),
                  "cannot copy the sparse model from " + src.string() + ": " + ec.message(),
                  "check free disk space and permissions");
  }
  const bool had_old = fs::exists(dst, ec);
  if (had_old) {
    fs::rename(dst, old, ec);
    if (ec) {
      const std::string why = ec.message();
      fs::remove_all(tmp, ec);
      throw IoError(dst.string(), "cannot replace the existing model: " + why,
                    "remove it by hand and run again");
    }
    RecordTemporary(old);
  }
  try {
    MoveOwned(tmp, dst);
  } catch (const Error&) {
    if (had_old) fs::rename(old, dst, ec);  // put the old model back
    fs::remove_all(tmp, ec);
    throw;
  }
  if (had_old) RemoveOwned(old);
}

}  // namespace perf::sfm_detail
