#include "viewer/view_files.h"

#include <array>
#include <string>

namespace perf::viewer {

namespace fs = std::filesystem;

namespace {

// Folders whose files the page shows, and single files it loads.
constexpr std::array<std::string_view, 6> kFolders = {"images", "masks", "foreground", "renders", "alpha", "preview"};
constexpr std::array<std::string_view, 2> kFiles = {"mesh.glb", "mesh.png"};
constexpr std::array<std::string_view, 4> kExtensions = {".png", ".jpg", ".jpeg", ".glb"};

bool Allowed(std::string_view name, const auto& list) {
  for (std::string_view s : list) {
    if (s == name) return true;
  }
  return false;
}

}  // namespace

std::optional<fs::path> ServableFile(const fs::path& workspace, std::string_view request) {
  if (request.empty() || request.size() > 1024 || request.front() == '/') return std::nullopt;
  for (char c : request) {
    if (c == '\\' || c == '\0' || static_cast<unsigned char>(c) < 0x20) return std::nullopt;
  }
  const fs::path rel(request);
  int parts = 0;
  for (const fs::path& part : rel) {
    const std::string p = part.string();
    if (p.empty() || p == "." || p == ".." || p.front() == '.') return std::nullopt;
    ++parts;
  }
  const std::string first = rel.begin()->string();
  const bool in_folder = parts >= 2 && Allowed(first, kFolders);
  const bool named = parts == 1 && Allowed(first, kFiles);
  if (!(in_folder || named)) return std::nullopt;
  std::string ext = rel.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (!Allowed(std::string_view(ext), kExtensions)) return std::nullopt;
  // Symbolic links inside the workspace could point anywhere: the resolved file must stay inside.
  std::error_code ec;
  const fs::path root = fs::weakly_canonical(workspace, ec);
  if (ec) return std::nullopt;
  const fs::path file = fs::weakly_canonical(workspace / rel, ec);
  if (ec || !fs::is_regular_file(file, ec)) return std::nullopt;
  const auto [r, f] = std::mismatch(root.begin(), root.end(), file.begin(), file.end());
  if (r != root.end()) return std::nullopt;
  return file;
}

const char* ContentTypeOf(const fs::path& file) {
  std::string ext = file.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".png") return "image/png";
  if (ext == ".jpg" || ext == ".jpeg") return "image/jpeg";
  if (ext == ".glb") return "model/gltf-binary";
  return "application/octet-stream";
}

}  // namespace perf::viewer
