// A user's inputs (photos, models, json) are read-only (DESIGN.md "Safety"). A reader registers
// each input it reads; from then on no write, move or removal of PERF's may reach that file
// (same device and inode, however it is named). Import records the registered inputs in the
// workspace (WORKSPACE/inputs.json), and every later command registers them again before it
// touches anything, so the protection outlives the process that read them.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace perf {

// Registers an input file for this process. Paths that do not exist are ignored.
void ProtectInput(const std::filesystem::path& path);

// Registers every regular file under `dir` (recursively, at most `limit` files; symbolic links
// are not followed): the photos folder a command is given, before it writes anything.
void ProtectInputFolder(const std::filesystem::path& dir, int limit = 200000);

// Whether `path` is a registered input.
bool IsProtectedInput(const std::filesystem::path& path);

// Throws InputError if `target` is a registered input; `what` says what PERF was about to do to
// it (e.g. "an output", "the previous run's file to move aside").
void CheckNotInput(const std::filesystem::path& target, std::string_view what = "an output");

// The registered inputs' paths (absolute), in no particular order.
std::vector<std::filesystem::path> ProtectedInputPaths();

// How the workspace's records name an input (scene.json's source, colmap/inputs.json): absolute and
// lexically normal. RecordedAs: whether `given` is the input `recorded` names, by that spelling or
// as the same file or folder by another (a trailing slash, a link).
std::string RecordedPath(const std::filesystem::path& given);
bool RecordedAs(const std::string& recorded, const std::filesystem::path& given);

// WORKSPACE/inputs.json: every registered input, written atomically.
std::filesystem::path InputRecordPath(const std::filesystem::path& workspace);
void WriteInputRecord(const std::filesystem::path& workspace);

// Registers the inputs WORKSPACE/inputs.json names (nothing when there is no record); returns
// how many. A damaged record is an InputError naming it.
int ProtectRecordedInputs(const std::filesystem::path& workspace);

}  // namespace perf
