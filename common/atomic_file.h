// Atomic writes: every output goes to a temporary file beside its target and is renamed over
// it only once complete, so an interrupted stage never leaves a half-written file that a later
// stage trusts. rename(2) within one directory is atomic on POSIX file systems.
#pragma once

#include <filesystem>
#include <functional>
#include <string_view>

namespace perf {

// A temporary path in the same directory as `target`, keeping its extension (so libraries that
// pick a format from the extension, like OpenImageIO, still do).
std::filesystem::path TempPathFor(const std::filesystem::path& target);

// Calls `write(tmp)` to write the file at a temporary path, then renames it to `target`.
// If `write` throws, the temporary file is removed and the exception propagates; `target` is
// untouched.
void WriteAtomically(const std::filesystem::path& target,
                     const std::function<void(const std::filesystem::path& tmp)>& write);

// Writes `contents` to `target` atomically.
void WriteFileAtomically(const std::filesystem::path& target, std::string_view contents);

// Creates `dir` (and parents) if needed and checks that files can be created in it; throws
// IoError naming the directory and what to do otherwise.
void EnsureWritableDirectory(const std::filesystem::path& dir);

// Reads a whole file; throws IoError if it cannot.
std::string ReadFileToString(const std::filesystem::path& path);

}  // namespace perf
