// Atomic, checked writes: every output is written in full to a temporary file beside its target,
// every write(2), fsync(2) and close(2) is checked, and only then is it renamed over the target,
// so a failed or interrupted stage never leaves a half-written file that a later stage trusts
// (rename(2) within one directory is atomic on POSIX file systems). A failure removes the
// temporary and throws IoError naming the final path.
//
// A user's inputs are read-only (DESIGN.md "Safety"): no atomic write may replace a file
// registered with ProtectInput (inputs.h), nor, once a command installed the workspace's record,
// any file PERF did not write (owned_files.h); temporaries and new folders are journalled there.
#pragma once

#include <filesystem>
#include <functional>
#include <iosfwd>
#include <string>
#include <string_view>

#include "common/inputs.h"

namespace perf {

// kDurable also fsyncs the file before the rename and its folder after it (checkpoints,
// scene.json: files a later run resumes from); kAtomic relies on the rename alone.
enum class Durability { kAtomic, kDurable };

// A temporary path in the same directory as `target`, keeping its extension:
// <stem>.tmp<pid>-<n><ext>. The name only helps a reader: the sweep removes a temporary because
// the workspace's journal lists it (owned_files.h), never because of its name.
std::filesystem::path TempPathFor(const std::filesystem::path& target);

// Throws InputError naming `target` when writing there would change a user's input (inputs.h) or
// a file PERF did not write (owned_files.h); `what` names the output. Every atomic write checks
// this; call it to refuse before any work is done.
void CheckMayReplace(const std::filesystem::path& target, std::string_view what = "an output");

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

// EnsureWritableDirectory for a folder PERF gives to a program it runs (COLMAP's): made here and
// journalled as PERF's as a whole, or one that already is; InputError naming it otherwise.
void EnsureWorkFolder(const std::filesystem::path& dir);

// Throws InputError naming `path` unless it is a regular file (or a link to one): a reader given
// a FIFO would wait forever and one given a device would read without end. IoError if missing.
void CheckRegularFile(const std::filesystem::path& path);

// Reads a whole regular file (never blocks on a FIFO nor reads a device without end); throws
// InputError for what is not a regular file and IoError if it cannot read it.
std::string ReadFileToString(const std::filesystem::path& path);

}  // namespace perf
