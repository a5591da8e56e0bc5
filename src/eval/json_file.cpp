// JSON file reading for the label loaders (nlohmann-json; its messages are folded onto one line).
#include "eval/json_file.h"

#include "core/error.h"
#include "core/fs.h"

namespace hgs::eval {

nlohmann::json read_json_file(const std::filesystem::path& file) {
  const std::string text = read_file_text(file);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    std::string msg = e.what();
    for (char& c : msg)
      if (c == '\n' || c == '\r') c = ' ';
    fail("{}: invalid JSON ({})", file.string(), msg);
  }
}

}  // namespace hgs::eval
