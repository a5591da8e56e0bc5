// Text cleaning for the CLIP tokenizer: see text_clean.h for the steps and what is not reproduced.
#include "clip/text_clean.h"

#include <locale.h>
#include <wctype.h>

#define PCRE2_CODE_UNIT_WIDTH 8
#include <pcre2.h>

#include <map>
#include <mutex>

#include "core/error.h"

namespace hgs::clip {

std::u32string utf8_decode(const std::string& s) {
  std::u32string out;
  out.reserve(s.size());
  const auto* p = reinterpret_cast<const unsigned char*>(s.data());
  size_t n = s.size(), i = 0;
  while (i < n) {
    unsigned c = p[i];
    int len = c < 0x80 ? 1 : (c >> 5) == 6 ? 2 : (c >> 4) == 14 ? 3 : (c >> 3) == 30 ? 4 : 0;
    if (len == 0 || i + len > n) {
      out.push_back(0xFFFD);
      ++i;
      continue;
    }
    char32_t cp = len == 1 ? c : len == 2 ? (c & 0x1F) : len == 3 ? (c & 0x0F) : (c & 0x07);
    bool ok = true;
    for (int k = 1; k < len; ++k) {
      if ((p[i + k] & 0xC0) != 0x80) {
        ok = false;
        break;
      }
      cp = (cp << 6) | (p[i + k] & 0x3F);
    }
    // Reject overlong forms, surrogates and values past U+10FFFF.
    static const char32_t min_cp[5] = {0, 0, 0x80, 0x800, 0x10000};
    if (!ok || cp < min_cp[len] || (cp >= 0xD800 && cp <= 0xDFFF) || cp > 0x10FFFF) {
      out.push_back(0xFFFD);
      ++i;
      continue;
    }
    out.push_back(cp);
    i += len;
  }
  return out;
}

std::string utf8_encode(char32_t c) {
  std::string o;
  if (c < 0x80) {
    o += char(c);
  } else if (c < 0x800) {
    o += char(0xC0 | (c >> 6));
    o += char(0x80 | (c & 0x3F));
  } else if (c < 0x10000) {
    o += char(0xE0 | (c >> 12));
    o += char(0x80 | ((c >> 6) & 0x3F));
    o += char(0x80 | (c & 0x3F));
  } else {
    o += char(0xF0 | (c >> 18));
    o += char(0x80 | ((c >> 12) & 0x3F));
    o += char(0x80 | ((c >> 6) & 0x3F));
    o += char(0x80 | (c & 0x3F));
  }
  return o;
}

std::string utf8_encode(const std::u32string& s) {
  std::string o;
  o.reserve(s.size());
  for (char32_t c : s) o += utf8_encode(c);
  return o;
}

namespace {

// Named character references: name (with ';' if required) -> code points. HTML5 lets the Latin-1 names and
// amp/lt/gt/quot (and their upper-case forms) appear without the semicolon.
const std::map<std::u32string, std::u32string>& entities() {
  static const std::map<std::u32string, std::u32string> table = [] {
    std::map<std::u32string, std::u32string> t;
    struct E {
      const char* name;
      char32_t cp;
      bool legacy;
    };
    static const E list[] = {
        {"amp", '&', true},       {"lt", '<', true},         {"gt", '>', true},         {"quot", '"', true},
        {"apos", '\'', false},    {"AMP", '&', true},        {"LT", '<', true},         {"GT", '>', true},
        {"QUOT", '"', true},      {"nbsp", 0xA0, true},      {"iexcl", 0xA1, true},     {"cent", 0xA2, true},
        {"pound", 0xA3, true},    {"curren", 0xA4, true},    {"yen", 0xA5, true},       {"sect", 0xA7, true},
        {"copy", 0xA9, true},     {"COPY", 0xA9, true},      {"laquo", 0xAB, true},     {"not", 0xAC, true},
        {"shy", 0xAD, true},      {"reg", 0xAE, true},       {"REG", 0xAE, true},       {"deg", 0xB0, true},
        {"plusmn", 0xB1, true},   {"sup2", 0xB2, true},      {"sup3", 0xB3, true},      {"micro", 0xB5, true},
        {"para", 0xB6, true},     {"middot", 0xB7, true},    {"raquo", 0xBB, true},     {"frac14", 0xBC, true},
        {"frac12", 0xBD, true},   {"frac34", 0xBE, true},    {"iquest", 0xBF, true},    {"Agrave", 0xC0, true},
        {"Aacute", 0xC1, true},   {"Auml", 0xC4, true},      {"Ccedil", 0xC7, true},    {"Eacute", 0xC9, true},
        {"Ntilde", 0xD1, true},   {"Ouml", 0xD6, true},      {"times", 0xD7, true},     {"Uuml", 0xDC, true},
        {"szlig", 0xDF, true},    {"agrave", 0xE0, true},    {"aacute", 0xE1, true},    {"acirc", 0xE2, true},
        {"auml", 0xE4, true},     {"ccedil", 0xE7, true},    {"egrave", 0xE8, true},    {"eacute", 0xE9, true},
        {"ecirc", 0xEA, true},    {"iacute", 0xED, true},    {"ntilde", 0xF1, true},    {"oacute", 0xF3, true},
        {"ouml", 0xF6, true},     {"divide", 0xF7, true},    {"uacute", 0xFA, true},    {"uuml", 0xFC, true},
        {"ndash", 0x2013, false}, {"mdash", 0x2014, false},  {"lsquo", 0x2018, false},  {"rsquo", 0x2019, false},
        {"sbquo", 0x201A, false}, {"ldquo", 0x201C, false},  {"rdquo", 0x201D, false},  {"bdquo", 0x201E, false},
        {"bull", 0x2022, false},  {"hellip", 0x2026, false}, {"prime", 0x2032, false},  {"euro", 0x20AC, false},
        {"trade", 0x2122, false}, {"larr", 0x2190, false},   {"rarr", 0x2192, false},   {"hearts", 0x2665, false},
        {"star", 0x2606, false},  {"half", 0xBD, false},     {"tab", '\t', false},      {"NewLine", '\n', false},
        {"excl", '!', false},     {"num", '#', false},       {"dollar", '$', false},    {"percnt", '%', false},
        {"lpar", '(', false},     {"rpar", ')', false},      {"ast", '*', false},       {"plus", '+', false},
        {"comma", ',', false},    {"period", '.', false},    {"sol", '/', false},       {"colon", ':', false},
        {"semi", ';', false},     {"equals", '=', false},    {"quest", '?', false},     {"commat", '@', false},
        {"lowbar", '_', false},   {"verbar", '|', false},    {"hyphen", 0x2010, false},
    };
    for (const E& e : list) {
      std::u32string n;
      for (const char* c = e.name; *c; ++c) n.push_back(char32_t(*c));
      t[n + U";"] = std::u32string(1, e.cp);
      if (e.legacy) t[n] = std::u32string(1, e.cp);
    }
    return t;
  }();
  return table;
}

// Windows-1252 meanings of the numeric references &#128; ... &#159; (HTML5 "invalid charrefs").
char32_t cp1252_fix(uint32_t n) {
  static const char32_t t[32] = {0x20AC, 0x81,   0x201A, 0x0192, 0x201E, 0x2026, 0x2020, 0x2021, 0x02C6, 0x2030, 0x0160,
                                 0x2039, 0x0152, 0x8D,   0x017D, 0x8F,   0x90,   0x2018, 0x2019, 0x201C, 0x201D, 0x2022,
                                 0x2013, 0x2014, 0x02DC, 0x2122, 0x0161, 0x203A, 0x0153, 0x9D,   0x017E, 0x0178};
  return t[n - 0x80];
}

bool is_hex(char32_t c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F'); }
bool is_dec(char32_t c) { return c >= '0' && c <= '9'; }

// One numeric reference value -> replacement text (Python html._replace_charref rules).
std::u32string numeric_ref(uint64_t num) {
  if (num == 0) return U"\uFFFD";
  if (num == 0x0D) return U"\r";
  if (num >= 0x80 && num <= 0x9F) return std::u32string(1, cp1252_fix(uint32_t(num)));
  if ((num >= 0xD800 && num <= 0xDFFF) || num > 0x10FFFF) return U"\uFFFD";
  if ((num >= 0x1 && num <= 0x8) || (num >= 0xE && num <= 0x1F) || (num >= 0x7F && num <= 0x9F) ||
      (num >= 0xFDD0 && num <= 0xFDEF) || num == 0xB || (num & 0xFFFE) == 0xFFFE)
    return U"";
  return std::u32string(1, char32_t(num));
}

}  // namespace

std::string html_unescape(const std::string& in) {
  if (in.find('&') == std::string::npos) return in;
  std::u32string s = utf8_decode(in), out;
  const auto& ent = entities();
  size_t i = 0, n = s.size();
  while (i < n) {
    if (s[i] != '&') {
      out.push_back(s[i++]);
      continue;
    }
    size_t j = i + 1;
    if (j < n && s[j] == '#') {
      bool hex = j + 1 < n && (s[j + 1] == 'x' || s[j + 1] == 'X');
      size_t k = j + 1 + (hex ? 1 : 0), start = k;
      uint64_t num = 0;
      while (k < n && (hex ? is_hex(s[k]) : is_dec(s[k]))) {
        char32_t c = s[k];
        uint32_t d = is_dec(c) ? c - '0' : (c | 0x20) - 'a' + 10;
        num = num > 0x7FFFFFFF ? num : num * (hex ? 16 : 10) + d;  // saturates far past U+10FFFF
        ++k;
      }
      if (k == start) {  // "&#" or "&#x" without digits: not a reference
        out.push_back(s[i++]);
        continue;
      }
      if (k < n && s[k] == ';') ++k;
      out += numeric_ref(num);
      i = k;
      continue;
    }
    // Named: up to 32 characters not in [\t\n\f <&#;], then an optional ';'.
    size_t k = j;
    while (k < n && k - j < 32 && s[k] != '\t' && s[k] != '\n' && s[k] != '\f' && s[k] != ' ' && s[k] != '<' &&
           s[k] != '&' && s[k] != '#' && s[k] != ';')
      ++k;
    if (k == j) {
      out.push_back(s[i++]);
      continue;
    }
    if (k < n && s[k] == ';') ++k;
    std::u32string name = s.substr(j, k - j);
    auto it = ent.find(name);
    if (it != ent.end()) {
      out += it->second;
    } else {
      bool found = false;
      for (size_t x = name.size() - 1; x > 1; --x) {  // longest legacy prefix
        auto p = ent.find(name.substr(0, x));
        if (p != ent.end()) {
          out += p->second;
          out += name.substr(x);
          found = true;
          break;
        }
      }
      if (!found) {
        out.push_back('&');
        out += name;
      }
    }
    i = k;
  }
  return utf8_encode(out);
}

namespace {

// ftfy subset: quotes, ligatures, full-width forms.
std::u32string ftfy_subset(const std::u32string& s) {
  std::u32string o;
  o.reserve(s.size());
  for (char32_t c : s) {
    if (c == 0x02BC || (c >= 0x2018 && c <= 0x201B)) o.push_back('\'');
    else if (c >= 0x201C && c <= 0x201F) o.push_back('"');
    else if (c == 0xFB00) o += U"ff";
    else if (c == 0xFB01) o += U"fi";
    else if (c == 0xFB02) o += U"fl";
    else if (c == 0xFB03) o += U"ffi";
    else if (c == 0xFB04) o += U"ffl";
    else if (c == 0xFB05) o += U"\u017Ft";
    else if (c == 0xFB06) o += U"st";
    else if (c >= 0xFF01 && c <= 0xFF5E) o.push_back(c - 0xFEE0);
    else if (c == 0x3000) o.push_back(' ');
    else o.push_back(c);
  }
  return o;
}

struct Pcre {
  pcre2_code* code = nullptr;
  explicit Pcre(const char* pattern) {
    int err;
    PCRE2_SIZE off;
    code = pcre2_compile(reinterpret_cast<PCRE2_SPTR>(pattern), PCRE2_ZERO_TERMINATED, PCRE2_UTF | PCRE2_UCP, &err,
                         &off, nullptr);
    if (!code) fail("internal error: cannot compile the whitespace pattern");
  }
  ~Pcre() { pcre2_code_free(code); }
};

std::string collapse_whitespace(const std::string& s) {
  static Pcre ws("[\\s\\x{85}]+");  // \s of Python's regex module, which CLIP uses: White_Space incl. NEL
  pcre2_match_data* md = pcre2_match_data_create_from_pattern(ws.code, nullptr);
  std::string out;
  PCRE2_SIZE pos = 0;
  while (pos <= s.size()) {
    int rc =
        pcre2_match(ws.code, reinterpret_cast<PCRE2_SPTR>(s.data()), s.size(), pos, PCRE2_NO_UTF_CHECK, md, nullptr);
    if (rc < 0) break;
    PCRE2_SIZE* ov = pcre2_get_ovector_pointer(md);
    out.append(s, pos, ov[0] - pos);
    out += ' ';
    pos = ov[1];
  }
  if (pos < s.size()) out.append(s, pos, std::string::npos);
  pcre2_match_data_free(md);
  // str.strip(): after the collapse the only str.isspace characters left are ' ' and U+001C-001F.
  static const char kStrip[] = " \x1c\x1d\x1e\x1f";
  size_t b = out.find_first_not_of(kStrip), e = out.find_last_not_of(kStrip);
  return b == std::string::npos ? std::string() : out.substr(b, e - b + 1);
}

char32_t to_lower(char32_t c) {
  if (c < 0x80) return (c >= 'A' && c <= 'Z') ? c + 32 : c;
  static locale_t loc = newlocale(LC_CTYPE_MASK, "C.UTF-8", locale_t(0));
  if (!loc) return c;
  return char32_t(towlower_l(wint_t(c), loc));
}

}  // namespace

std::string clean_text(const std::string& s) {
  std::string t = utf8_encode(ftfy_subset(utf8_decode(s)));
  t = html_unescape(html_unescape(t));
  t = collapse_whitespace(t);  // also strips both ends (Python's strip() + whitespace_clean)
  // Python's str.lower: simple mappings plus the two context-free/contextual special cases of Unicode's
  // SpecialCasing that it applies: U+0130 -> "i\u0307" and the final sigma (capital sigma at the end of a
  // word -> U+03C2), with approximations of Unicode's Cased and Case_Ignorable properties.
  std::u32string u = utf8_decode(t), lower;
  lower.reserve(u.size());
  static locale_t loc = newlocale(LC_CTYPE_MASK, "C.UTF-8", locale_t(0));
  // "Cased": a lower/upper case letter or one with another case form (approximates Unicode's Cased property).
  auto cased = [&](char32_t c) {
    if (c < 0x80) return (c | 0x20) >= 'a' && (c | 0x20) <= 'z';
    return loc && (iswlower_l(wint_t(c), loc) || iswupper_l(wint_t(c), loc) ||
                   towlower_l(wint_t(c), loc) != wint_t(c) || towupper_l(wint_t(c), loc) != wint_t(c));
  };
  // Case_Ignorable: general categories Mn, Me, Cf, Lm, Sk plus the word-break MidLetter / MidNumLet /
  // Single_Quote characters (Unicode's definition), tested with PCRE2's Unicode properties.
  static Pcre ign(
      "^[\\p{Mn}\\p{Me}\\p{Cf}\\p{Lm}\\p{Sk}'.:\\x{B7}\\x{387}\\x{55F}\\x{5F4}\\x{2018}\\x{2019}\\x{2024}\\x{2027}\\x{"
      "FE13}\\x{FE52}\\x{FE55}\\x{FF07}\\x{FF0E}\\x{FF1A}]$");
  pcre2_match_data* md = pcre2_match_data_create_from_pattern(ign.code, nullptr);
  auto ignorable = [&](char32_t c) {
    std::string e = utf8_encode(c);
    return pcre2_match(ign.code, reinterpret_cast<PCRE2_SPTR>(e.data()), e.size(), 0, PCRE2_NO_UTF_CHECK, md,
                       nullptr) >= 0;
  };
  auto final_sigma = [&](size_t i) {
    size_t k = i;
    while (k > 0 && ignorable(u[k - 1])) --k;
    if (k == 0 || !cased(u[k - 1])) return false;
    size_t j = i + 1;
    while (j < u.size() && ignorable(u[j])) ++j;
    return !(j < u.size() && cased(u[j]));
  };
  for (size_t i = 0; i < u.size(); ++i) {
    char32_t c = u[i];
    if (c == 0x130) {
      lower += U"i\u0307";
    } else if (c == 0x3A3 && final_sigma(i)) {
      lower.push_back(0x3C2);
    } else {
      lower.push_back(to_lower(c));
    }
  }
  pcre2_match_data_free(md);
  return utf8_encode(lower);
}

}  // namespace hgs::clip
