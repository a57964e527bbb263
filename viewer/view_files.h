// What `perf view` may serve from a workspace (DESIGN.md "Safety": the viewer only reads): a file
// under one of a fixed set of the workspace's output folders, or one of its named outputs, by a
// path that is relative, has no "." or ".." part, and resolves inside the workspace. Everything
// else is refused, whatever the encoding it arrived in (the server decodes the URL once first).
#pragma once

#include <filesystem>
#include <optional>
#include <string_view>

namespace perf::viewer {

// The file `request` (a decoded path below /files/, e.g. "renders/test/DSCF5605.png") names in
// `workspace`, when it may be served and is a regular file there; nullopt otherwise.
std::optional<std::filesystem::path> ServableFile(const std::filesystem::path& workspace, std::string_view request);

// The Content-Type of a servable file (by its extension).
const char* ContentTypeOf(const std::filesystem::path& file);

}  // namespace perf::viewer
