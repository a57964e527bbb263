// PERF changes only what PERF made (DESIGN.md "Safety"). Every file or folder PERF creates for a
// workspace is written to the workspace's journal, WORKSPACE/.perf/owned.jsonl, with its identity
// (a finished file: its size and modification time to the nanosecond, which a copy of the workspace
// keeps; a log, folder or temporary: also its device and inode) before it can matter;
// PERF replaces, appends to, moves or removes a path only when the journal names that path with
// the very file that is there now. Anything else in the way (a user's file, a planted link, the
// output of an older PERF that kept no journal, a file changed since) is "not ours": refused by
// name, never overwritten. The rule fails closed: a missing journal protects everything.
//
// Temporaries are journalled when they are made, so the sweep of what killed runs left behind
// reads the journal and removes only those (a user's photo named like a temporary is never one).
//
// The journal is this process's once a command installs it (UseOwnershipRecord, under the
// workspace lock). Without one, as in library use and unit tests, only inputs are protected
// (inputs.h). Appends to the journal are single O_APPEND writes, so threads may write outputs at once.
#pragma once

#include <filesystem>
#include <functional>
#include <string_view>

#include "common/unique_fd.h"

namespace perf {

// WORKSPACE/.perf: the journal, the lock's note and export's staging folder live here.
std::filesystem::path PrivateFolder(const std::filesystem::path& workspace);

// Installs WORKSPACE/.perf/owned.jsonl as this process's record (made if missing) and reads it.
// Throws InputError when WORKSPACE/.perf is not a folder (a file or a link) and IoError when the
// journal cannot be opened.
void UseOwnershipRecord(const std::filesystem::path& workspace);
bool HasOwnershipRecord();
// Forgets the installed record (tests; a command ends with its process).
void DropOwnershipRecord();

// Whether the file, link or folder at `path` (never followed) is one the record says PERF made
// and has not changed since; or lies in a folder PERF gave to a program it ran (RecordWorkFolder).
// True for everything without a record (there is nothing to check against).
bool IsOwned(const std::filesystem::path& path);

// Throws InputError (exit 2) naming the folder when `path` lies in the workspace below a folder
// that is a symbolic link (a write would land outside the workspace); nothing without a record.
void CheckNoLinkOnTheWay(const std::filesystem::path& path);

// Throws InputError (exit 2) naming `target` unless nothing is there or IsOwned(target), or when
// it lies below a linked folder of the workspace (CheckNoLinkOnTheWay). `what`
// names the output ("a render", "the --log-json log"); the hint says to choose another path.
void CheckReplaceable(const std::filesystem::path& target, std::string_view what = "an output");

// Journal entries (no-ops without a record). `tmp` was just made by this process (O_EXCL, mkdir):
// a temporary the sweep may remove once this process is gone.
void RecordTemporary(const std::filesystem::path& tmp);
// `final_path` will hold the finished file now at `written` (about to be renamed there).
void RecordOutput(const std::filesystem::path& final_path, const std::filesystem::path& written);
// A folder PERF just made (EnsureWritableDirectory): removable once it is empty.
void RecordFolder(const std::filesystem::path& dir);
// A folder PERF just made for a program it runs (COLMAP's database and models): what is in it is
// PERF's to replace or remove as a whole.
void RecordWorkFolder(const std::filesystem::path& dir);

// For a file PERF reads whole and writes back whole, keeping what a user edited in it (scene.json,
// which users edit to leave photos out): runs `read`, and if it returned and the file did not
// change meanwhile, takes the file as PERF's, so that the write back may replace it. A link or
// anything but a regular file is never taken. Replacing it with something new (a new import) is
// still refused until the user moves the edited file away.
void ReadBackAsOwned(const std::filesystem::path& path, const std::function<void()>& read);

// Renames an owned `from` to `to` (CheckReplaceable), journalling it at its new path.
void MoveOwned(const std::filesystem::path& from, const std::filesystem::path& to);
// Removes `path` (a file; a folder with everything in it) when IsOwned; throws InputError naming
// it when something that is not ours is there; nothing there is fine.
void RemoveOwned(const std::filesystem::path& path);
// Removes the files of `dir` (recursively) that are ours and the owned folders left empty;
// leaves everything else. Returns whether `dir` is gone.
bool RemoveOwnedTree(const std::filesystem::path& dir);

// Opens a log for appending (append true) or afresh, without following a link at `path`: a new
// file is made (O_EXCL) and journalled; an existing one must be ours, else InputError naming it.
UniqueFd OpenLog(const std::filesystem::path& path, bool append, std::string_view what);
// A log's size and time once PERF is done writing it (open as `fd`), so that a copy of the
// workspace still knows it as PERF's (best effort; a killed run leaves its inode only).
void RecordLogWritten(const std::filesystem::path& path, int fd);

// Removes the temporaries the record lists whose process has ended, if the path still holds the
// temporary that process made; then rewrites the journal without entries that name nothing any
// more. Returns the number removed. Call with the workspace lock held.
int SweepOwnedTemporaries();

}  // namespace perf
