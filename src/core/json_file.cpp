// JSON file reading (nlohmann-json; its messages are folded onto one line).
#include "core/json_file.h"

#include "core/error.h"
#include "core/fs.h"

namespace hgs {

nlohmann::json read_json_file(const std::filesystem::path& file) {
  const std::string text = read_file_text(file);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for a number too large
    std::string msg = e.what();
    for (char& c : msg)
      if (c == '\n' || c == '\r') c = ' ';
    fail("{}: invalid JSON ({})", file.string(), msg);
  }
}

}  // namespace hgs
