// CLIP's text cleaning before tokenisation (basic_clean + whitespace_clean + lower()):
//   1. a subset of ftfy.fix_text: invalid UTF-8 -> U+FFFD, curly quotes -> ASCII quotes, Latin ligatures
//      (U+FB00-FB06) expanded, full-width ASCII forms (U+FF01-FF5E) and the ideographic space made half-width;
//   2. html.unescape applied twice (numeric references with the HTML5 replacement rules, and the common named
//      entities — not the full 2231-entry HTML5 table);
//   3. whitespace runs (Unicode \s, via PCRE2 with UCP) collapsed to one space, ends stripped;
//   4. Unicode lower case like Python's str.lower: the C.UTF-8 locale's simple mapping, plus U+0130 -> "i\u0307"
//      and the final sigma rule (letters judged by iswalpha rather than Unicode's "cased" property).
// Not reproduced from ftfy: mojibake repair (fix_encoding), NFC normalisation, terminal-escape removal.
#pragma once
#include <string>

namespace hgs::clip {

std::u32string utf8_decode(const std::string& s);  // invalid sequences -> U+FFFD
std::string utf8_encode(const std::u32string& s);
std::string utf8_encode(char32_t c);

std::string html_unescape(const std::string& s);  // one pass, like Python's html.unescape
std::string clean_text(const std::string& s);     // steps 1-4 above

}  // namespace hgs::clip
