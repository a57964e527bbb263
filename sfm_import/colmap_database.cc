#include "sfm_import/colmap_database.h"

#include <sqlite3.h>

#include <memory>

#include "common/errors.h"

namespace perf::colmap {
namespace {

struct CloseDb {
  void operator()(sqlite3* db) const { sqlite3_close(db); }
};
struct FinalizeStatement {
  void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
};

[[noreturn]] void Fail(const std::filesystem::path& database, const std::string& what, sqlite3* db) {
  throw IoError(database.string(),
                StrCat("cannot read COLMAP's database: ", what, " (", db != nullptr ? sqlite3_errmsg(db) : "no memory", ")"),
                "it is PERF's own work file: run the command again to make it anew");
}

}  // namespace

std::map<std::string, DatabaseImage> ReadDatabaseImages(const std::filesystem::path& database) {
  sqlite3* raw = nullptr;
  const int opened = sqlite3_open_v2(database.c_str(), &raw, SQLITE_OPEN_READONLY, nullptr);
  const std::unique_ptr<sqlite3, CloseDb> db(raw);
  if (opened != SQLITE_OK) Fail(database, "open", raw);
  sqlite3_stmt* stmt = nullptr;
  if (sqlite3_prepare_v2(raw, "SELECT image_id, name, camera_id FROM images", -1, &stmt, nullptr) != SQLITE_OK) {
    Fail(database, "its table of images", raw);
  }
  const std::unique_ptr<sqlite3_stmt, FinalizeStatement> query(stmt);
  std::map<std::string, DatabaseImage> images;
  int step = SQLITE_ROW;
  while ((step = sqlite3_step(stmt)) == SQLITE_ROW) {
    const unsigned char* name = sqlite3_column_text(stmt, 1);
    if (name == nullptr) continue;
    images[reinterpret_cast<const char*>(name)] = {static_cast<uint32_t>(sqlite3_column_int64(stmt, 0)),
                                                   static_cast<uint32_t>(sqlite3_column_int64(stmt, 2))};
  }
  if (step != SQLITE_DONE) Fail(database, "a row of its table of images", raw);
  return images;
}

}  // namespace perf::colmap
