// Reading a JSON label file with one-line errors that name the file.
#pragma once
#include <filesystem>
#include <nlohmann/json.hpp>

namespace hgs::eval {

// Parses the whole file; a missing file or a syntax error raises hgs::Error "<file>: invalid JSON (...)".
nlohmann::json read_json_file(const std::filesystem::path& file);

}  // namespace hgs::eval
