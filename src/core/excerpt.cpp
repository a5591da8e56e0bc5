// Short one-line quotes of user text: see excerpt.h.
#include "core/excerpt.h"

#include <fmt/format.h>

namespace hgs {

std::string excerpt(const std::string& text, size_t max_chars) {
  std::string out;
  size_t chars = 0, total = 0;
  for (size_t i = 0; i < text.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    const bool starts = (c & 0xC0) != 0x80;  // a code point's first byte (or a stray byte)
    if (starts) ++total;
    if (starts && chars == max_chars) continue;  // counting the rest only
    if (!starts && chars == max_chars && total > max_chars) continue;
    if (starts) ++chars;
    if (c == '\n') out += "\\n";
    else if (c == '\t') out += "\\t";
    else if (c < 0x20 || c == 0x7F) out += fmt::format("\\x{:02x}", c);
    else out += char(c);
  }
  if (total > max_chars) out += fmt::format("… ({} characters)", total);
  return out;
}

}  // namespace hgs
