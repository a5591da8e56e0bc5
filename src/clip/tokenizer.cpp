// CLIP BPE tokenizer: see tokenizer.h.
#include "clip/tokenizer.h"

#include <zlib.h>

#define PCRE2_CODE_UNIT_WIDTH 8
#include <pcre2.h>

#include <climits>
#include <mutex>

#include "clip/assets.h"
#include "clip/text_clean.h"
#include "core/error.h"

namespace hgs::clip {

struct Tokenizer::Regex {
  pcre2_code* code = nullptr;
  ~Regex() { pcre2_code_free(code); }
};

namespace {

std::string read_gz(const std::filesystem::path& path) {
  gzFile f = gzopen(path.string().c_str(), "rb");
  if (!f) {
    if (!std::filesystem::exists(path)) fail("{}: file not found", path.string());
    fail("{}: cannot open for reading", path.string());
  }
  std::string out;
  char buf[1 << 16];
  int n;
  while ((n = gzread(f, buf, sizeof buf)) > 0) out.append(buf, size_t(n));
  int err = 0;
  const char* msg = gzerror(f, &err);
  bool bad = n < 0 || (err != Z_OK && err != Z_STREAM_END);
  std::string m = bad && msg ? msg : "";
  gzclose(f);
  if (bad) fail("{}: corrupt gzip data ({})", path.string(), m);
  return out;
}

}  // namespace

Tokenizer::Tokenizer(const std::filesystem::path& bpe_gz) : re_(std::make_unique<Regex>()) {
  // GPT-2 byte encoder: printable bytes map to themselves, the others to 256, 257, ... in byte order.
  byte_enc_.resize(256);
  std::vector<int> order;  // bytes in the order of bytes_to_unicode().values()
  auto printable = [](int b) { return (b >= '!' && b <= '~') || (b >= 0xA1 && b <= 0xAC) || (b >= 0xAE && b <= 0xFF); };
  for (int b = 0; b < 256; ++b)
    if (printable(b)) {
      byte_enc_[b] = utf8_encode(char32_t(b));
      order.push_back(b);
    }
  int extra = 0;
  for (int b = 0; b < 256; ++b)
    if (!printable(b)) {
      byte_enc_[b] = utf8_encode(char32_t(256 + extra++));
      order.push_back(b);
    }

  std::string text = read_gz(bpe_gz);
  std::vector<std::pair<std::string, std::string>> merges;
  size_t pos = 0;
  int line_no = 0;
  const int n_merges = kVocab - 256 - 256 - 2;  // 48894: lines 1 .. 48894 after the version line
  while (pos < text.size() && int(merges.size()) < n_merges) {
    size_t e = text.find('\n', pos);
    if (e == std::string::npos) e = text.size();
    std::string line = text.substr(pos, e - pos);
    pos = e + 1;
    if (line_no++ == 0) continue;  // "#version: ..." header
    size_t sp = line.find(' ');
    if (sp == std::string::npos || sp == 0 || sp + 1 >= line.size())
      fail("{}: line {} is not a BPE merge \"a b\"", bpe_gz.string(), line_no);
    merges.emplace_back(line.substr(0, sp), line.substr(sp + 1));
  }
  if (int(merges.size()) != n_merges)
    fail("{}: {} merges found, {} expected (truncated vocabulary?)", bpe_gz.string(), merges.size(), n_merges);
  for (int b : order) vocab_.push_back(byte_enc_[b]);
  for (int b : order) vocab_.push_back(byte_enc_[b] + "</w>");
  for (size_t i = 0; i < merges.size(); ++i) {
    vocab_.push_back(merges[i].first + merges[i].second);
    merge_rank_.emplace(merges[i].first + " " + merges[i].second, int(i));
  }
  vocab_.push_back("<|startoftext|>");
  vocab_.push_back("<|endoftext|>");
  for (size_t i = 0; i < vocab_.size(); ++i) encoder_.emplace(vocab_[i], int(i));

  // U+0345 is excluded from the last class: under IGNORECASE Python's regex module matches it with none of
  // the alternatives (its case fold is a letter), so CLIP drops it.
  static const char* pattern =
      "<\\|startoftext\\|>|<\\|endoftext\\|>|'s|'t|'re|'ve|'m|'ll|'d|[\\p{L}]+|[\\p{N}]|[^\\s\\p{L}\\p{N}\\x{345}]+";
  int err;
  PCRE2_SIZE off;
  re_->code = pcre2_compile(reinterpret_cast<PCRE2_SPTR>(pattern), PCRE2_ZERO_TERMINATED,
                            PCRE2_UTF | PCRE2_UCP | PCRE2_CASELESS, &err, &off, nullptr);
  if (!re_->code) fail("internal error: cannot compile CLIP's split pattern (PCRE2 error {})", err);
}

Tokenizer::~Tokenizer() = default;

const Tokenizer& Tokenizer::shared() {
  static std::unique_ptr<Tokenizer> tok;
  static std::once_flag once;
  std::call_once(once, [] { tok = std::make_unique<Tokenizer>(find_asset("clip/bpe_simple_vocab_16e6.txt.gz")); });
  return *tok;
}

std::vector<std::string> Tokenizer::bpe(const std::string& piece) const {
  if (piece == "<|startoftext|>" || piece == "<|endoftext|>") return {piece};
  // Split into code points (each a UTF-8 string); the last one gets '</w>'.
  std::vector<std::string> word;
  for (size_t i = 0; i < piece.size();) {
    unsigned char c = piece[i];
    size_t len = c < 0x80 ? 1 : (c >> 5) == 6 ? 2 : (c >> 4) == 14 ? 3 : 4;
    word.push_back(piece.substr(i, len));
    i += len;
  }
  if (word.empty()) return {};
  word.back() += "</w>";
  std::string key;
  while (word.size() > 1) {
    int best = INT_MAX;
    size_t best_i = 0;
    for (size_t i = 0; i + 1 < word.size(); ++i) {
      key.assign(word[i]).append(" ").append(word[i + 1]);
      auto it = merge_rank_.find(key);
      if (it != merge_rank_.end() && it->second < best) best = it->second, best_i = i;
    }
    if (best == INT_MAX) break;
    // Merge every occurrence of the best pair, left to right (non-overlapping), as CLIP does.
    const std::string first = word[best_i], second = word[best_i + 1];
    std::vector<std::string> merged;
    merged.reserve(word.size());
    for (size_t i = 0; i < word.size();) {
      if (i + 1 < word.size() && word[i] == first && word[i + 1] == second) {
        merged.push_back(first + second);
        i += 2;
      } else {
        merged.push_back(word[i++]);
      }
    }
    word.swap(merged);
  }
  return word;
}

std::vector<int> Tokenizer::encode(const std::string& raw) const {
  std::string text = clean_text(raw);
  std::vector<int> ids;
  pcre2_match_data* md = pcre2_match_data_create_from_pattern(re_->code, nullptr);
  PCRE2_SIZE pos = 0;
  while (pos < text.size()) {
    int rc = pcre2_match(re_->code, reinterpret_cast<PCRE2_SPTR>(text.data()), text.size(), pos, PCRE2_NO_UTF_CHECK, md,
                         nullptr);
    if (rc < 0) break;
    PCRE2_SIZE* ov = pcre2_get_ovector_pointer(md);
    if (ov[1] == ov[0]) {  // cannot happen with this pattern; guard against an endless loop
      ++pos;
      continue;
    }
    std::string piece;
    if (text.compare(ov[0], ov[1] - ov[0], "<|startoftext|>") == 0 ||
        text.compare(ov[0], ov[1] - ov[0], "<|endoftext|>") == 0) {
      piece = text.substr(ov[0], ov[1] - ov[0]);
    } else {
      for (PCRE2_SIZE i = ov[0]; i < ov[1]; ++i) piece += byte_enc_[static_cast<unsigned char>(text[i])];
    }
    for (auto& sym : bpe(piece)) {
      auto it = encoder_.find(sym);
      if (it == encoder_.end()) fail("internal error: BPE symbol not in the CLIP vocabulary");
      ids.push_back(it->second);
    }
    pos = ov[1];
  }
  pcre2_match_data_free(md);
  return ids;
}

std::vector<int> Tokenizer::tokenize(const std::string& text, int context) const {
  std::vector<int> ids{kSot};
  auto body = encode(text);
  ids.insert(ids.end(), body.begin(), body.end());
  ids.push_back(kEot);
  if (int(ids.size()) > context) {
    ids.resize(size_t(context));
    ids.back() = kEot;
  }
  return ids;
}

std::vector<int> Tokenizer::tokenize_padded(const std::string& text, int context) const {
  auto ids = tokenize(text, context);
  ids.resize(size_t(context), 0);
  return ids;
}

}  // namespace hgs::clip
