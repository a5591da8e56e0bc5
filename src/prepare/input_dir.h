// The output folder of the input stage (internal to photos.cpp / video.cpp): file stamps (size + mtime) that
// say whether a source or an output changed, the record out_dir/inputs.json, and the removal of files that are
// no longer part of the input, so that the folder COLMAP reads always equals the input.
#pragma once
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

namespace hgs::prepare {

inline constexpr const char* kInputsJson = "inputs.json";
inline constexpr const char* kFramesTmp = ".frames.tmp";  // video frames before the blur filter
inline constexpr int kInputsFormat = 1;                   // bump when the outputs for the same options change

struct FileStamp {
  uint64_t size = 0;
  int64_t mtime_ns = 0;
  bool operator==(const FileStamp&) const = default;
};

// `p` absolute with links, "." and ".." resolved and no trailing slash (as far as it exists; the rest lexically
// normalised): one spelling for every way of typing the same folder or file.
std::filesystem::path resolved_path(const std::filesystem::path& p);

// The stamp of a file; all zero when it does not exist.
FileStamp file_stamp(const std::filesystem::path& path);
nlohmann::json stamp_json(const FileStamp& s);
bool stamp_matches(const nlohmann::json& j, const FileStamp& s);

// out_dir/inputs.json, or null when it is absent or unreadable (then nothing is reused).
nlohmann::json read_inputs_record(const std::filesystem::path& out_dir);
void write_inputs_record(const std::filesystem::path& out_dir, const nlohmann::json& record);

// Removes the regular files of out_dir whose name is not in `keep` (inputs.json is kept).
void remove_other_files(const std::filesystem::path& out_dir, const std::set<std::string>& keep);

}  // namespace hgs::prepare
