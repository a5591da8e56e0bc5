// UTF-8 checks for text that arrives as bytes (file names, HTTP query text): strict validation, and a form with
// every byte of an invalid sequence replaced so that the text can go into JSON (which must be UTF-8).
#pragma once
#include <string>
#include <string_view>

namespace hgs {

// Strict UTF-8: no overlong forms, surrogates or code points above U+10FFFF.
bool valid_utf8(std::string_view s);

// `s` with each byte that is not part of a valid UTF-8 sequence replaced by `with` (valid text is unchanged).
std::string utf8_or(std::string_view s, char with);

}  // namespace hgs
