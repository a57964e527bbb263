#include "sfm_import/import_images.h"

#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <map>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/system_memory.h"
#include "workspace/scene.h"

namespace fs = std::filesystem;

namespace perf::import_detail {
namespace {

PixelFormat OutputFormat(PixelFormat f) {
  return f == PixelFormat::kFloat ? PixelFormat::kHalf : f;  // half is plenty for photos
}

std::string ReplaceExtension(const std::string& name, const std::string& ext) {
  return fs::path(name).replace_extension(ext).generic_string();
}

void ProcessImage(const ImageJob& job, const ImportOptions& o, const fs::path& ws) {
  ImageInfo info;
  Image img = ReadImage(job.source, &info);
  if (job.undistorter && !job.undistorter->is_identity()) img = job.undistorter->Apply(img);
  img = ResizeImage(img, job.out_width, job.out_height);
  Image alpha;
  Image rgb = ToRgb(img, {o.background.x(), o.background.y(), o.background.z()},
                    job.alpha_rel.empty() ? nullptr : &alpha);
  const PixelFormat out = OutputFormat(info.format);
  EnsureWritableDirectory((ws / job.out_rel).parent_path());
  WriteImage(ws / job.out_rel, rgb, out);
  if (!alpha.empty()) {
    EnsureWritableDirectory((ws / job.alpha_rel).parent_path());
    WriteImage(ws / job.alpha_rel, alpha, out == PixelFormat::kUInt8 ? PixelFormat::kUInt8 : PixelFormat::kUInt16);
  }
}

// Decoding, undistorting and resizing hold about three float copies of a photo at once; the
// number of photos in flight is bounded so that they fit in the available memory.
int Concurrency(const ImportOptions& o, const LargestPhoto& largest) {
  const int threads = o.num_threads > 0 ? o.num_threads : tbb::info::default_concurrency();
  const int64_t per_job = 3 * largest.bytes;
  // Before any photo is decoded: a small file may decode to gigabytes (a PNG of 20000 x 20000).
  CheckFitsInMemory(per_job, StrCat("importing ", largest.path.string()),
                    "downscale the photos first (e.g. with oiiotool --resize)");
  const int64_t available = AvailableMemory();
  return available > 0 && per_job > 0 ? static_cast<int>(std::clamp<int64_t>(available / per_job, 1, threads))
                                      : threads;
}

}  // namespace

std::string OutputExtension(PixelFormat f) { return f == PixelFormat::kHalf || f == PixelFormat::kFloat ? ".exr" : ".png"; }

void LargestPhoto::Consider(const fs::path& photo, const ImageInfo& info) {
  if (DecodedBytes(info) <= bytes) return;
  bytes = DecodedBytes(info);
  path = photo;
}

void RunJobs(const std::vector<ImageJob>& jobs, const ImportOptions& o, const LargestPhoto& largest) {
  // Nothing may land on an input, or on any file PERF did not write, whatever the folders' names:
  // checked before the first write.
  for (const ImageJob& job : jobs) {
    for (const std::string& rel : {job.out_rel, job.alpha_rel}) {
      if (rel.empty()) continue;
      const std::string what = StrCat(rel == job.out_rel ? "the workspace image" : "the alpha image", " of ", job.source.string());
      CheckMayReplace(o.workspace / rel, what);
    }
  }
  CheckMayReplace(o.workspace / "scene.json", "scene.json");
  std::atomic<int> done{0};
  const int total = static_cast<int>(jobs.size());
  tbb::task_arena arena(Concurrency(o, largest));
  arena.execute([&] {
    tbb::parallel_for(0, total, [&](int i) {
      ProcessImage(jobs[i], o, o.workspace);
      const int d = ++done;
      if (o.progress) o.progress(d, total);
    });
  });
}

std::string ClaimOutputName(const std::string& folder, const std::string& name, const std::string& ext,
                            std::set<std::string>* taken) {
  const std::string base = ReplaceExtension(WorkspaceSafeName(name), "");
  std::string rel = folder + "/" + base + ext;
  for (int k = 2; !taken->insert(rel).second; ++k) rel = StrCat(folder, "/", base, "-", k, ext);
  return rel;
}

void CheckOneSize(const std::vector<std::pair<fs::path, ImageInfo>>& infos, const std::string& group,
                  const std::string& hint) {
  std::map<std::pair<int, int>, int> count;
  for (const auto& [path, info] : infos) ++count[{info.width, info.height}];
  if (count.size() <= 1) return;
  const auto common = std::max_element(count.begin(), count.end(), [](const auto& a, const auto& b) {
                        return a.second < b.second;
                      })->first;
  for (const auto& [path, info] : infos) {
    if (std::pair{info.width, info.height} == common) continue;
    throw InputError(path.string(), "size", StrCat(info.width, "x", info.height),
                     StrCat("differs from the other ", count[common], " photos of ", group, " (", common.first, "x",
                            common.second, ")"),
                     hint);
  }
}

}  // namespace perf::import_detail
