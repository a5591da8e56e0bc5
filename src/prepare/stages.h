// Which stages of `hgs prepare` are complete, kept in SCENE/prepare/state.json so that a rerun skips them. Each
// stage has a key: a hash of its options and of the keys of the stages it reads, so a change upstream (other
// photos, another matcher, other weights) makes every stage downstream of it run again, and no other. A stage is marked
// started (with its key) before it writes anything and done only once its outputs are complete; a per-view stage
// started with the same key keeps the views already written, one started with another key starts over.
#pragma once
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

namespace hgs::prepare {

// 16 hex digits (FNV-1a, 64 bits) of `text`.
std::string hash_key(const std::string& text);

// 16 hex digits (FNV-1a) of a file's bytes; "" when it cannot be read.
std::string hash_file_content(const std::filesystem::path& path);

// A file's identity for a stage key: absolute path, size and modification time.
std::string hash_file_identity(const std::string& path);

class StageLog {
 public:
  // Reads `file` when it exists (a damaged file counts as empty), else writes an empty one.
  explicit StageLog(std::filesystem::path file);
  bool done(const std::string& stage, const std::string& key) const;
  bool started(const std::string& stage, const std::string& key) const;  // started or done with this key
  void start(const std::string& stage, const std::string& key);
  void finish(const std::string& stage, const std::string& key, double seconds, const nlohmann::json& info = {});
  double seconds(const std::string& stage) const;  // of the run that completed it
  const nlohmann::json& info(const std::string& stage) const;

 private:
  void save() const;
  std::filesystem::path file_;
  nlohmann::json j_ = nlohmann::json::object();
};

}  // namespace hgs::prepare
