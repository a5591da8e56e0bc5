// Stage records of `hgs prepare` (see stages.h).
#include "prepare/stages.h"

#include <fmt/format.h>

#include <fstream>

#include "core/fs.h"

namespace hgs::prepare {
namespace fs = std::filesystem;

std::string hash_key(const std::string& text) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : text) h = (h ^ c) * 1099511628211ull;
  return fmt::format("{:016x}", h);
}

std::string hash_file_content(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return "";
  uint64_t h = 1469598103934665603ull;
  char buf[1 << 16];
  while (in.read(buf, sizeof buf) || in.gcount() > 0) {
    for (std::streamsize i = 0; i < in.gcount(); ++i) h = (h ^ static_cast<unsigned char>(buf[i])) * 1099511628211ull;
    if (!in) break;
  }
  return fmt::format("{:016x}", h);
}

std::string hash_file_identity(const std::string& path) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  const auto t = fs::last_write_time(path, ec).time_since_epoch().count();
  return fmt::format("{}:{}:{}", fs::absolute(path).string(), size, t);
}

StageLog::StageLog(fs::path file) : file_(std::move(file)) {
  if (!fs::exists(file_)) {
    save();  // marks the folder as one hgs prepare made, before anything else is written there
    return;
  }
  try {
    j_ = nlohmann::json::parse(read_file_text(file_));
  } catch (const std::exception&) {
    j_ = nlohmann::json::object();
  }
  if (!j_.is_object()) j_ = nlohmann::json::object();
}

bool StageLog::done(const std::string& stage, const std::string& key) const {
  auto it = j_.find(stage);
  return it != j_.end() && it->value("key", "") == key && it->value("done", false);
}

bool StageLog::started(const std::string& stage, const std::string& key) const {
  auto it = j_.find(stage);
  return it != j_.end() && it->value("key", "") == key;
}

void StageLog::start(const std::string& stage, const std::string& key) {
  j_[stage] = {{"key", key}, {"done", false}};
  save();
}

void StageLog::finish(const std::string& stage, const std::string& key, double seconds, const nlohmann::json& info) {
  j_[stage] = {{"key", key}, {"done", true}, {"seconds", seconds}, {"info", info}};
  save();
}

double StageLog::seconds(const std::string& stage) const {
  auto it = j_.find(stage);
  return it == j_.end() ? 0.0 : it->value("seconds", 0.0);
}

const nlohmann::json& StageLog::info(const std::string& stage) const {
  static const nlohmann::json empty = nlohmann::json::object();
  auto it = j_.find(stage);
  if (it == j_.end() || !it->contains("info")) return empty;
  return (*it)["info"];
}

void StageLog::save() const {
  ensure_dir(file_.parent_path());
  atomic_write_text(file_, j_.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
}

}  // namespace hgs::prepare
