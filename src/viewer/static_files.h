// Static files of the browser front end: where the built files live (beside the executable) and a safe
// mapping from a URL path to a file inside that folder only (no "..", no absolute paths, no symlink escape).
#pragma once
#include <filesystem>
#include <optional>
#include <string>

namespace hgs::viewer {

// <folder of the running executable>/viewer (where the build installs the front end).
std::filesystem::path default_static_dir();

// The file that URL path `url_path` (already percent-decoded, starting with '/') names inside `root`, or
// nullopt when it escapes the folder, contains NUL/backslash/".." segments or names no regular file.
// "/" and folder paths map to their index.html.
std::optional<std::filesystem::path> resolve_static(const std::filesystem::path& root, const std::string& url_path);

// Content type for a file name by its extension (application/octet-stream when unknown).
const char* mime_type(const std::filesystem::path& file);

}  // namespace hgs::viewer
