// The language space of the realistic world (`hgs synth --world realistic`, the default): simulated CLIP
// ViT-B/16 text embeddings and MaskCLIP-style dense image features with the statistics real ones have
// (docs/formats.md, "The realistic world", cites each figure), instead of the simple world's one random unit
// vector per phrase.
//
// Every phrase is built from words of a small lexicon: an attribute ("red"), a noun ("mug"), the noun's category
// ("tableware", the hypernym a user types) and a coarse group ("kitchen item"). A noun's meaning is
//   n(noun) = normalise(0.35 u(group) + 0.55 u(category) + 0.76 u(noun))
// with u(word) a fixed random unit vector of the word, so mug ~ teapot (one category) > mug ~ apple (nothing
// shared). Text and image embeddings live in two cones (CLIP's modality gap): a text is
//   t = normalise(kTextShared g_T + content),   content = normalise(kNounWeight n + kAttrWeight u(attr))
// so that any two names are 0.6-0.9 apart in cosine, and an image region of a thing is
//   v = normalise(kImageShared g_I + kContent content + per-view bias + noise),   g_I . g_T = kGap
// so that an image's cosine with its own name is about 0.3, with an unrelated name about 0.18.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace hgs::synth {

// What a thing or a phrase is made of (any field may be empty).
struct Lexeme {
  std::string attribute;  // "red"
  std::string noun;       // "mug"
  std::string category;   // "tableware": the natural hypernym
  std::string group;      // "kitchen item": the coarse group the category belongs to
};

// The lexicon entry of a class or surface name of the synthetic world ("red mug", "wooden table", "floor", "sky").
// Fails naming the phrase when it has none.
Lexeme lexeme_of(const std::string& name);
bool in_lexicon(const std::string& name);
// The synonym phrase of a class ("coffee cup" for "red mug"): another noun of the same category, no attribute.
std::string synonym_of(const std::string& name);
// The attribute phrase a user types for a thing by its colour or material ("the red one"); empty when none.
std::string attribute_phrase(const Lexeme& x);
// The family of a colour near another ("green" for "lime"; its vector shares 0.6 with the family's); empty for
// the others.
std::string colour_family(const std::string& attribute);

// Simulated CLIP text embedding [dim] of a phrase made of `x` (unit norm); `extra_word` adds a word of its own
// (a synonym's own noun, "one" of an attribute phrase) with weight 0.45 beside the content.
std::vector<float> text_embedding(const Lexeme& x, int dim, const std::string& extra_word = "");
// A generic phrase (LERF's canonical "object", "things", ...; a distractor made of unknown words): the shared
// text direction plus the phrase's own vector.
std::vector<float> generic_text_embedding(const std::string& phrase, int dim);

// The image-side meaning of a thing: content [dim], not normalised (the part of a region's feature that says what
// it is; sky and nothing hit have none).
std::vector<float> image_content(const Lexeme& x, int dim);

// Constants of the space (docs/formats.md).
inline constexpr double kTextShared = 1.5;   // weight of the shared text direction g_T against content 1
inline constexpr double kImageShared = 1.6;  // weight of the shared image direction g_I
inline constexpr double kContent = 0.35;     // weight of the content in an image feature
inline constexpr double kGap = 0.25;         // g_I . g_T: the cones' overlap (unrelated pairs' cosine ~0.18)
inline constexpr double kNounWeight = 0.89, kAttrWeight = 0.45;
inline constexpr int kGridShort = 28;  // dense feature cells on the image's shorter side (448 px / patch 16)

// The shared directions (unit vectors).
std::vector<float> text_direction(int dim);
std::vector<float> image_direction(int dim);

}  // namespace hgs::synth
