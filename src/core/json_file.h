// Reading a whole JSON file with one-line errors that name the file.
#pragma once
#include <filesystem>
#include <nlohmann/json.hpp>

namespace hgs {

// Parses the whole file. A file that cannot be read raises read_file_text's hgs::Error (naming the file); a syntax
// error or a number out of range raises hgs::Error "<file>: invalid JSON (<nlohmann's message on one line>)".
nlohmann::json read_json_file(const std::filesystem::path& file);

}  // namespace hgs
