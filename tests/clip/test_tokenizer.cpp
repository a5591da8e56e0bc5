// CLIP tokenizer: known ids, and ids of tricky strings (punctuation, numbers, apostrophes, non-ASCII, HTML
// entities, truncation, empty) from an independent Python implementation (tests/data/clip/tokens.json).
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "clip/assets.h"
#include "clip/text_clean.h"
#include "clip/tokenizer.h"
#include "clip_test_util.h"
#include "core/error.h"
#include "core/fs.h"
#include "test_util.h"

using namespace hgs::clip;

TEST(ClipTokenizer, KnownIds) {
  const Tokenizer& tok = Tokenizer::shared();
  EXPECT_EQ(tok.tokenize("a photo of a cat"), (std::vector<int>{49406, 320, 1125, 539, 320, 2368, 49407}));
  EXPECT_EQ(tok.tokenize("A  Photo of a CAT. "), (std::vector<int>{49406, 320, 1125, 539, 320, 2368, 269, 49407}));
  EXPECT_EQ(tok.tokenize(""), (std::vector<int>{49406, 49407}));
  EXPECT_EQ(tok.token_string(2368), "cat</w>");
  auto padded = tok.tokenize_padded("a photo of a cat");
  ASSERT_EQ(padded.size(), 77u);
  EXPECT_EQ(padded[6], 49407);
  EXPECT_EQ(padded[7], 0);
}

TEST(ClipTokenizer, Truncation) {
  const Tokenizer& tok = Tokenizer::shared();
  std::string long_text;
  for (int i = 0; i < 200; ++i) long_text += "cat ";
  auto ids = tok.tokenize(long_text);
  ASSERT_EQ(ids.size(), 77u);
  EXPECT_EQ(ids.front(), Tokenizer::kSot);
  EXPECT_EQ(ids.back(), Tokenizer::kEot);
  EXPECT_EQ(ids[75], 2368);
  EXPECT_EQ(tok.tokenize(long_text, 10).size(), 10u);
}

TEST(ClipTokenizer, MatchesPythonReference) {
  std::ifstream in(hgs::test::clip_data("tokens.json"));
  ASSERT_TRUE(in) << "tests/data/clip/tokens.json missing";
  nlohmann::json cases = nlohmann::json::parse(in);
  ASSERT_GE(cases.size(), 10u);
  const Tokenizer& tok = Tokenizer::shared();
  for (auto& c : cases) {
    std::string text = c["text"].get<std::string>();
    EXPECT_EQ(tok.tokenize(text), c["ids"].get<std::vector<int>>()) << "text: " << text;
  }
}

// 500 random strings over many Unicode blocks (marks, controls, odd spaces, CJK, emoji, full-width forms).
TEST(ClipTokenizer, MatchesPythonOnRandomUnicode) {
  std::ifstream in(hgs::test::clip_data("tokens_fuzz.json"));
  ASSERT_TRUE(in) << "tests/data/clip/tokens_fuzz.json missing";
  nlohmann::json cases = nlohmann::json::parse(in);
  ASSERT_EQ(cases.size(), 500u);
  const Tokenizer& tok = Tokenizer::shared();
  int bad = 0;
  for (auto& c : cases) {
    std::string text = c["text"].get<std::string>();
    if (tok.tokenize(text) != c["ids"].get<std::vector<int>>() && ++bad <= 5)
      ADD_FAILURE() << "text: " << c["text"].dump();
  }
  EXPECT_EQ(bad, 0);
}

TEST(ClipTokenizer, HtmlUnescape) {
  EXPECT_EQ(html_unescape("&amp; &lt;b&gt; &quot;x&quot; &#39;y&#39; &#x263A;"), "& <b> \"x\" 'y' \xE2\x98\xBA");
  EXPECT_EQ(html_unescape("&amp;amp;"), "&amp;");
  EXPECT_EQ(html_unescape(html_unescape("&amp;amp;")), "&");
  EXPECT_EQ(html_unescape("&copy 2024 &ampx"), "\xC2\xA9 2024 &x");        // legacy names without ';'
  EXPECT_EQ(html_unescape("&#128;&#0;&#1;"), "\xE2\x82\xAC\xEF\xBF\xBD");  // cp1252 fix, NUL -> U+FFFD, ^A dropped
  EXPECT_EQ(html_unescape("&unknownentity; & &# &#x;"), "&unknownentity; & &# &#x;");
  EXPECT_EQ(html_unescape("&#99999999999;"), "\xEF\xBF\xBD");
}

TEST(ClipTokenizer, CleanText) {
  EXPECT_EQ(clean_text("  Hello\t\n  WORLD  "), "hello world");
  EXPECT_EQ(clean_text("\xC3\x89T\xC3\x89 \xD0\x9F\xD0\xA0"),
            "\xC3\xA9t\xC3\xA9 \xD0\xBF\xD1\x80");  // ÉTÉ ПР -> été пр
  EXPECT_EQ(clean_text("\xE2\x80\x9Cq\xE2\x80\x9D \xEF\xAC\x81"), "\"q\" fi");
  EXPECT_EQ(clean_text("a\xC2\xA0"
                       "b\xE3\x80\x80"
                       "c"),
            "a b c");  // NBSP and ideographic space are whitespace
  EXPECT_EQ(clean_text("bad \xFF byte"), "bad \xEF\xBF\xBD byte");
}

TEST(ClipTokenizer, AssetLookupAndBadVocabulary) {
  hgs::test::TempDir t;
  std::filesystem::create_directories(t / "clip");
  auto real = find_asset("clip/bpe_simple_vocab_16e6.txt.gz");
  std::filesystem::copy_file(real, t / "clip" / "bpe_simple_vocab_16e6.txt.gz");
  setenv("HGS_ASSETS", t.path.c_str(), 1);
  EXPECT_EQ(find_asset("clip/bpe_simple_vocab_16e6.txt.gz"), t / "clip" / "bpe_simple_vocab_16e6.txt.gz");
  setenv("HGS_ASSETS", (t / "nothing-here").c_str(), 1);  // falls back to the next locations
  EXPECT_TRUE(std::filesystem::exists(find_asset("clip/bpe_simple_vocab_16e6.txt.gz")));
  unsetenv("HGS_ASSETS");
  try {
    find_asset("clip/absent.txt");
    ADD_FAILURE() << "expected an error";
  } catch (const hgs::Error& e) {
    EXPECT_NE(std::string(e.what()).find("HGS_ASSETS"), std::string::npos) << e.what();
  }
  // A truncated gzip or a vocabulary with too few merges is a one-line error naming the file.
  auto bytes = hgs::read_file_bytes(real);
  hgs::atomic_write_bytes(t / "short.gz", bytes.data(), bytes.size() / 2);
  EXPECT_THROW(Tokenizer(t / "short.gz"), hgs::Error);
  try {
    Tokenizer(t / "missing.gz");
    ADD_FAILURE() << "expected an error";
  } catch (const hgs::Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing.gz"), std::string::npos) << e.what();
  }
}
