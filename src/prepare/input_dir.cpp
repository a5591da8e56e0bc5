// File stamps, inputs.json and stale-file removal of the input stage (input_dir.h).
#include "prepare/input_dir.h"

#include "core/error.h"
#include "core/fs.h"

namespace hgs::prepare {
namespace fs = std::filesystem;

fs::path resolved_path(const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(fs::absolute(p, ec), ec);
  if (ec) r = fs::absolute(p).lexically_normal();
  if (r.has_parent_path() && r.filename().empty()) r = r.parent_path();
  return r;
}

FileStamp file_stamp(const fs::path& path) {
  std::error_code ec;
  FileStamp s;
  const auto size = fs::file_size(path, ec);
  if (ec) return s;
  const auto t = fs::last_write_time(path, ec);
  if (ec) return s;
  s.size = size;
  s.mtime_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
  return s;
}

nlohmann::json stamp_json(const FileStamp& s) { return {{"size", s.size}, {"mtime_ns", s.mtime_ns}}; }

bool stamp_matches(const nlohmann::json& j, const FileStamp& s) {
  return j.is_object() && j.value("size", uint64_t(0)) == s.size && j.value("mtime_ns", int64_t(0)) == s.mtime_ns &&
         s.size > 0;
}

nlohmann::json read_inputs_record(const fs::path& out_dir) {
  const fs::path p = out_dir / kInputsJson;
  std::error_code ec;
  if (!fs::is_regular_file(p, ec)) return nullptr;
  try {
    nlohmann::json j = nlohmann::json::parse(read_file_text(p));
    if (j.is_object() && j.value("format", 0) == kInputsFormat) return j;
  } catch (const std::exception&) {
  }
  return nullptr;
}

void write_inputs_record(const fs::path& out_dir, const nlohmann::json& record) {
  nlohmann::json j = record;
  j["format"] = kInputsFormat;
  atomic_write_text(out_dir / kInputsJson, j.dump(1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
}

void remove_other_files(const fs::path& out_dir, const std::set<std::string>& keep) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(out_dir, ec)) {
    const std::string name = e.path().filename().string();
    if (!e.is_regular_file(ec) || name == kInputsJson || keep.count(name)) continue;
    if (!fs::remove(e.path(), ec) && ec)
      fail("{}: cannot remove a stale input image ({})", e.path().string(), ec.message());
  }
}

}  // namespace hgs::prepare
