// What a COLMAP database (SQLite, written by feature_extractor) says of its photos: each one's
// image id and camera id. COLMAP numbers photos in the order its threads read them, not by name,
// and a model handed to point_triangulator or image_registrator must use the database's ids
// (ghost_register.h). Read-only; COLMAP 3.8's schema (table `images`).
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

namespace perf::colmap {

struct DatabaseImage {
  uint32_t image_id = 0;
  uint32_t camera_id = 0;
};

// name -> ids. Throws IoError naming the file when it cannot be opened or read as one.
std::map<std::string, DatabaseImage> ReadDatabaseImages(const std::filesystem::path& database);

}  // namespace perf::colmap
