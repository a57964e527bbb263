// An export's files reach the workspace as one set (DESIGN.md "Safety"): perf export writes every
// file into a staging folder, WORKSPACE/.perf/export/ (the workspace's own layout), and only once
// all of them are written does CommitStagedExport move them into place and remove the old set's
// files that the new set no longer has (an empty mesh has no mesh.png). A failure before the
// commit leaves the old set and its export.json as they were; a kill during the commit's moves is
// finished by the next command that locks the workspace (FinishStagedExport). So export.json
// always describes the files on disk.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

namespace perf::exporter {

// WORKSPACE/.perf/export: emptied of what a failed export left, and made.
std::filesystem::path StartStagedExport(const std::filesystem::path& workspace);

// The group an output belongs to, from its path relative to the workspace: "masks",
// "foreground", "volume", "mesh", "renders", "sparse_refined" (empty for none).
std::string ExportGroup(const std::filesystem::path& relative);

// The workspace's export.json, or null when there is none, it is not PERF's or it cannot be read.
nlohmann::json ReadOldManifest(const std::filesystem::path& workspace);

// The files a manifest (export.json, or null) lists, relative to the workspace and inside it;
// entries that are not such paths are skipped.
std::vector<std::filesystem::path> ManifestFiles(const nlohmann::json& manifest);

// `files` (relative, staged, export.json among them) replace the old set's files of the `groups`
// written this time; the old manifest's other files of those groups are removed if PERF wrote
// them. Throws InputError naming a destination that PERF did not write, before anything moves.
void CommitStagedExport(const std::filesystem::path& workspace, const std::vector<std::filesystem::path>& files,
                        const std::set<std::string>& groups, const nlohmann::json& old_manifest);

// Called with the workspace locked: finishes a commit a killed export left half done, or removes
// the staging folder of an export that failed or was killed before its commit.
void FinishStagedExport(const std::filesystem::path& workspace);

}  // namespace perf::exporter
