// CLIP's byte-level BPE tokenizer (the "simple tokenizer" of OpenAI CLIP and open_clip):
//   text -> clean_text (text_clean.h) -> pieces by CLIP's split pattern
//   <|startoftext|>|<|endoftext|>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+ (PCRE2, UTF + UCP,
//   caseless) -> each piece's UTF-8 bytes mapped to printable code points (GPT-2 byte encoder), '</w>' appended
//   to the last symbol -> greedy lowest-rank pair merging with the 48894 merges of bpe_simple_vocab_16e6 ->
//   ids in the 49408-entry vocabulary (256 bytes, 256 bytes+'</w>', merges, then <|startoftext|> = 49406 and
//   <|endoftext|> = 49407).
#pragma once
#include <filesystem>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

namespace hgs::clip {

class Tokenizer {
 public:
  static constexpr int kSot = 49406, kEot = 49407, kVocab = 49408;

  // Reads the gzip'ed merges file (default: assets/clip/bpe_simple_vocab_16e6.txt.gz via find_asset).
  explicit Tokenizer(const std::filesystem::path& bpe_gz);
  ~Tokenizer();
  static const Tokenizer& shared();  // lazily loaded default instance (thread-safe)

  // BPE ids of `text` without start/end tokens.
  std::vector<int> encode(const std::string& text) const;
  // [sot] + encode(text) + [eot], truncated to `context` tokens with the last one forced to eot (open_clip's
  // tokenize), NOT padded: its length is min(len, context).
  std::vector<int> tokenize(const std::string& text, int context = 77) const;
  // Same, zero-padded to exactly `context` ids (what open_clip.tokenize returns).
  std::vector<int> tokenize_padded(const std::string& text, int context = 77) const;
  // The vocabulary entry of an id (byte-encoded form, e.g. "cat</w>").
  const std::string& token_string(int id) const { return vocab_.at(id); }

 private:
  std::vector<std::string> bpe(const std::string& piece) const;  // piece in byte-encoded form -> symbols
  std::vector<std::string> byte_enc_;                            // [256] UTF-8 of each byte's code point
  std::vector<std::string> vocab_;                               // id -> string
  std::unordered_map<std::string, int> encoder_;                 // string -> id
  std::unordered_map<std::string, int> merge_rank_;              // "a b" -> rank
  struct Regex;
  std::unique_ptr<Regex> re_;
};

}  // namespace hgs::clip
