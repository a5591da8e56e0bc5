// Safe photo names for COLMAP (names.h).
#include "prepare/names.h"

#include <algorithm>
#include <cctype>

#include "core/utf8.h"

namespace hgs::prepare {

std::string colmap_safe_name(const std::string& name) {
  std::string s = utf8_or(name, '_');
  for (char& c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7F || c == '\\') c = '_';
  }
  for (size_t i = 0; i < s.size() && s[i] == ' '; ++i) s[i] = '_';
  for (size_t i = s.size(); i > 0 && s[i - 1] == ' '; --i) s[i - 1] = '_';
  return s;
}

bool has_image_extension(const std::filesystem::path& path) {
  std::string e = path.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e == ".jpg" || e == ".jpeg" || e == ".jpe" || e == ".png";
}

}  // namespace hgs::prepare
