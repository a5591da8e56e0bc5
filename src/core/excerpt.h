// User text quoted in an error message, kept short and on one line (issue 60: a query error echoed the whole
// 1 MB query): at most `max_chars` characters (UTF-8 code points; never cut inside one), control characters
// escaped (\n, \t, \xNN), and "… (N characters)" after a cut. Used for query texts, phrases, option names and
// view names that the CLI, the viewer and the Python binding echo.
#pragma once
#include <cstddef>
#include <string>

namespace hgs {

inline constexpr size_t kExcerptChars = 80;

std::string excerpt(const std::string& text, size_t max_chars = kExcerptChars);

}  // namespace hgs
