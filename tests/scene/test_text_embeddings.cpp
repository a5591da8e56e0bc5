// The scene's shared helpers: phrase files, the text_embeddings.json writer and the COLMAP model folder of a scene.
#include <gtest/gtest.h>

#include <algorithm>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "scene/colmap.h"
#include "scene/text_embeddings.h"
#include "test_util.h"

namespace hgs {
namespace {
namespace fs = std::filesystem;
using test::TempDir;

TEST(TextEmbeddings, PhraseFilesSkipEmptyLinesAndDropCarriageReturns) {
  TempDir t;
  atomic_write_text(t / "a.txt", "red mug\r\n\n  chair\r\nwooden table");
  EXPECT_EQ(read_phrase_file(t / "a.txt"), (std::vector<std::string>{"red mug", "  chair", "wooden table"}));
  atomic_write_text(t / "b.txt", "\n\r\n");
  EXPECT_TRUE(read_phrase_file(t / "b.txt").empty());
  EXPECT_THROW(read_phrase_file(t / "missing.txt"), Error);
}

TEST(TextEmbeddings, WrittenEmbeddingsReadBackPerPhraseAndReplaceEqualOnes) {
  TempDir t;
  nlohmann::json te = {{"kept", {0.5, -0.25}}, {"red mug", {9.0, 9.0}}};
  add_text_embeddings(te, {"red mug", "object"}, {1.f, 2.f, 3.f, 4.f}, 2);
  write_text_embeddings(t / "text_embeddings.json", te);
  const std::string text = read_file_text(t / "text_embeddings.json");
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1) << "one line";
  const nlohmann::json j = nlohmann::json::parse(text);
  EXPECT_EQ(j.size(), 3u);
  EXPECT_EQ(j["red mug"].get<std::vector<float>>(), (std::vector<float>{1, 2}));
  EXPECT_EQ(j["object"].get<std::vector<float>>(), (std::vector<float>{3, 4}));
  EXPECT_EQ(j["kept"].get<std::vector<float>>(), (std::vector<float>{0.5f, -0.25f}));
}

TEST(TextEmbeddings, CanonicalPhrasesAreLerfs) {
  EXPECT_EQ(std::vector<std::string>(kCanonicalPhrases.begin(), kCanonicalPhrases.end()),
            (std::vector<std::string>{"object", "things", "stuff", "texture"}));
}

TEST(ColmapModelDir, SparseZeroElseSparseWithCamerasElseAnErrorNamingTheScene) {
  TempDir t;
  ensure_dir(t / "s" / "sparse");
  try {
    colmap_model_dir(t / "s");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find((t / "s").string() + ": no COLMAP model"), std::string::npos) << e.what();
  }
  atomic_write_text(t / "s" / "sparse" / "cameras.bin", "");
  EXPECT_EQ(colmap_model_dir(t / "s"), t / "s" / "sparse");
  ensure_dir(t / "s" / "sparse" / "0");
  EXPECT_EQ(colmap_model_dir(t / "s"), t / "s" / "sparse" / "0");
}

}  // namespace
}  // namespace hgs
