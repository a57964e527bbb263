#include "export/export_set.h"

#include <unistd.h>

#include <algorithm>

#include "common/atomic_file.h"
#include "common/errors.h"
#include "common/owned_files.h"

namespace perf::exporter {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

fs::path StagingFolder(const fs::path& workspace) { return PrivateFolder(workspace) / "export"; }
// The commit's plan: the files to move and those to remove. Written once every file is staged.
fs::path CommitPlan(const fs::path& workspace) { return PrivateFolder(workspace) / "export-commit.json"; }

// Carries out a written plan: moves the staged files into place (export.json last), removes the
// old set's files, then the plan and the staging folder. Moves already done are skipped, so a
// plan cut short by a kill is finished by running it again.
void ApplyPlan(const fs::path& workspace, const json& plan) {
  const fs::path staging = StagingFolder(workspace);
  std::vector<fs::path> files;
  for (const auto& f : plan.at("files")) files.emplace_back(f.get<std::string>());
  std::stable_partition(files.begin(), files.end(), [](const fs::path& f) { return f != "export.json"; });
  for (const fs::path& f : files) {
    const fs::path from = staging / f, to = workspace / f;
    std::error_code ec;
    if (!fs::exists(from, ec)) continue;  // moved before a kill
    EnsureWritableDirectory(to.parent_path());
    MoveOwned(from, to);
  }
  for (const auto& f : plan.at("remove")) {
    const fs::path path = workspace / f.get<std::string>();
    std::error_code ec;
    if (!fs::exists(path, ec) || !IsOwned(path)) continue;  // not PERF's: left as it is
    RemoveOwned(path);
    if (IsOwned(path.parent_path())) ::rmdir(path.parent_path().c_str());  // only when empty
  }
  RemoveOwned(CommitPlan(workspace));
  RemoveOwnedTree(staging);
}

}  // namespace

fs::path StartStagedExport(const fs::path& workspace) {
  const fs::path staging = StagingFolder(workspace);
  RemoveOwnedTree(staging);
  EnsureWritableDirectory(staging);
  return staging;
}

std::string ExportGroup(const fs::path& relative) {
  const std::string first = relative.begin() == relative.end() ? "" : relative.begin()->string();
  if (first == "masks" || first == "foreground" || first == "renders" || first == "sparse_refined") return first;
  if (first == "volume.vdb") return "volume";
  if (relative.parent_path().empty() && relative.stem() == "mesh") return "mesh";
  return "";
}

json ReadOldManifest(const fs::path& workspace) {
  const fs::path path = workspace / "export.json";
  std::error_code ec;
  if (!fs::exists(path, ec) || !IsOwned(path)) return nullptr;
  try {
    json j = json::parse(ReadFileToString(path));
    return j.is_object() ? j : json(nullptr);
  } catch (const std::exception&) {
    return nullptr;
  }
}

std::vector<fs::path> ManifestFiles(const json& manifest) {
  std::vector<fs::path> files;
  if (!manifest.is_object() || !manifest.contains("files") || !manifest["files"].is_array()) return files;
  for (const auto& f : manifest["files"]) {
    if (!f.is_string()) continue;
    const fs::path rel = fs::path(f.get<std::string>()).lexically_normal();
    if (rel.is_absolute() || rel.empty() || *rel.begin() == "..") continue;  // a garbled manifest's
    files.push_back(rel);
  }
  return files;
}

void CommitStagedExport(const fs::path& workspace, const std::vector<fs::path>& files,
                        const std::set<std::string>& groups, const json& old_manifest) {
  std::set<std::string> written;
  json plan{{"files", json::array()}, {"remove", json::array()}};
  for (const fs::path& f : files) {
    CheckReplaceable(workspace / f, "the export");  // before anything moves
    written.insert(f.generic_string());
    plan["files"].push_back(f.generic_string());
  }
  for (const fs::path& rel : ManifestFiles(old_manifest)) {
    if (groups.count(ExportGroup(rel)) && !written.count(rel.generic_string())) plan["remove"].push_back(rel.generic_string());
  }
  WriteFileAtomically(CommitPlan(workspace), plan.dump(1) + "\n", Durability::kDurable);
  ApplyPlan(workspace, plan);
}

void FinishStagedExport(const fs::path& workspace) {
  const fs::path plan_path = CommitPlan(workspace);
  std::error_code ec;
  if (fs::exists(plan_path, ec) && IsOwned(plan_path)) {
    json plan;
    try {
      plan = json::parse(ReadFileToString(plan_path));
      plan.at("files");
      plan.at("remove");
    } catch (const std::exception&) {
      plan = nullptr;  // torn (it is written atomically, so only by a hand): the staged set is dropped
    }
    if (plan.is_object()) {
      ApplyPlan(workspace, plan);
      return;
    }
    RemoveOwned(plan_path);
  }
  if (fs::exists(StagingFolder(workspace), ec)) RemoveOwnedTree(StagingFolder(workspace));
}

}  // namespace perf::exporter
