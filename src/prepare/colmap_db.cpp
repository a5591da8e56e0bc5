// COLMAP's database read back with SQLite (colmap_db.h).
#include "prepare/colmap_db.h"

#include <sqlite3.h>

#include "core/error.h"

namespace hgs::prepare {

std::set<std::string> images_with_features(const std::filesystem::path& database) {
  sqlite3* db = nullptr;
  const int rc = sqlite3_open_v2(database.c_str(), &db, SQLITE_OPEN_READONLY, nullptr);
  auto done = [&] { sqlite3_close(db); };
  if (rc != SQLITE_OK) {
    const std::string why = db ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
    done();
    fail("{}: cannot open COLMAP's database ({})", database.string(), why);
  }
  const char* sql =
      "SELECT images.name FROM images JOIN keypoints ON keypoints.image_id = images.image_id "
      "JOIN descriptors ON descriptors.image_id = images.image_id";
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db, sql, -1, &st, nullptr) != SQLITE_OK) {
    const std::string why = sqlite3_errmsg(db);
    done();
    fail("{}: not a COLMAP database with features ({})", database.string(), why);
  }
  std::set<std::string> names;
  int step;
  while ((step = sqlite3_step(st)) == SQLITE_ROW) {
    const unsigned char* t = sqlite3_column_text(st, 0);
    if (t) names.insert(reinterpret_cast<const char*>(t));
  }
  const std::string why = step == SQLITE_DONE ? "" : sqlite3_errmsg(db);
  sqlite3_finalize(st);
  done();
  if (!why.empty()) fail("{}: cannot read COLMAP's database ({})", database.string(), why);
  return names;
}

}  // namespace hgs::prepare
