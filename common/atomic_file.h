// Atomic, checked writes: every output is written in full to a temporary file beside its target,
// every write(2), fsync(2) and close(2) is checked, and only then is it renamed over the target,
// so a failed or interrupted stage never leaves a half-written file that a later stage trusts
// (rename(2) within one directory is atomic on POSIX file systems). A failure removes the
// temporary and throws IoError naming the final path.
//
// A user's inputs are read-only (DESIGN.md "Safety"): the readers of photos and models register
// them with ProtectInput, and no atomic write may replace a registered file.
#pragma once

#include <filesystem>
#include <functional>
#include <iosfwd>
#include <string>
#include <string_view>

namespace perf {

// kDurable also fsyncs the file before the rename and its folder after it (checkpoints,
// scene.json: files a later run resumes from); kAtomic relies on the rename alone.
enum class Durability { kAtomic, kDurable };

// A temporary path in the same directory as `target`, keeping its extension:
// <stem>.tmp<pid>-<n><ext>. SweepStaleTemporaries (workspace_lock.h) recognises the pattern.
std::filesystem::path TempPathFor(const std::filesystem::path& target);

// Writes `contents` to `target` atomically (see above).
void WriteFileAtomically(const std::filesystem::path& target, std::string_view contents,
                         Durability durability = Durability::kAtomic);

// Lets `write` fill an in-memory stream, then writes it with WriteFileAtomically. For writers
// whose library reports errors poorly on files: the bytes reach the disk through checked calls.
void WriteStreamAtomically(const std::filesystem::path& target, const std::function<void(std::ostream&)>& write,
                           Durability durability = Durability::kAtomic);

// Calls `write(tmp)` to write the file at a temporary path with a library that takes a path, then
// checks (fsync, close) and renames it to `target`. Prefer WriteStreamAtomically: a library may
// swallow a failed write that no later check can see.
void WriteAtomically(const std::filesystem::path& target,
                     const std::function<void(const std::filesystem::path& tmp)>& write,
                     Durability durability = Durability::kAtomic);

// Creates `dir` (and parents) if needed and checks that files can be created in it; throws
// IoError naming the directory and what to do otherwise.
void EnsureWritableDirectory(const std::filesystem::path& dir);

// Reads a whole file; throws IoError if it cannot.
std::string ReadFileToString(const std::filesystem::path& path);

// Registers an input file (a photo, a model file, a json) for this process: from now on an
// atomic write whose target is that same file (same device and inode, however it is named)
// throws InputError instead. Paths that do not exist are ignored.
void ProtectInput(const std::filesystem::path& path);

// Throws InputError if `target` is a registered input; `what` says which output it would be.
void CheckNotInput(const std::filesystem::path& target, std::string_view what = "an output");

}  // namespace perf
