// The realistic world's lexicon and its simulated CLIP embeddings (language.h): every word a fixed random unit
// vector seeded by its text (the same in every scene, as a real text encoder), nouns built from their category and
// group, colours from their family (lime ~ green), then the two shared modality directions.
#include "synth/language.h"

#include <cmath>
#include <map>

#include "core/error.h"
#include "synth/rng.h"

namespace hgs::synth {
namespace {

std::vector<double> word(const std::string& w, int dim) {
  Rng rng(hash_string("word:" + w));
  std::vector<double> v(dim);
  double s = 0;
  for (auto& x : v) {
    x = rng.normal();
    s += x * x;
  }
  for (auto& x : v) x /= std::sqrt(s);
  return v;
}

void add(std::vector<double>& a, const std::vector<double>& b, double w) {
  for (size_t i = 0; i < a.size(); ++i) a[i] += w * b[i];
}

std::vector<double> normalised(std::vector<double> v) {
  double s = 0;
  for (double x : v) s += x * x;
  if (s > 0)
    for (auto& x : v) x /= std::sqrt(s);
  return v;
}

std::vector<float> to_float(const std::vector<double>& v) { return std::vector<float>(v.begin(), v.end()); }

struct Entry {
  Lexeme x;
  std::string synonym;
};

// One line per class of the world's pool (world.cpp) and per background surface.
// clang-format off
const std::map<std::string, Entry>& lexicon() {
  static const std::map<std::string, Entry> m = {
      {"red mug",               {{"red", "mug", "cup", "kitchenware"}, "coffee cup"}},
      {"white teapot",          {{"white", "teapot", "pot", "kitchenware"}, "tea kettle"}},
      {"green apple",           {{"green", "apple", "fruit", "food"}, "granny smith"}},
      {"purple donut",          {{"purple", "donut", "pastry", "food"}, "doughnut"}},
      {"blue book",             {{"blue", "book", "reading material", "office supply"}, "hardcover"}},
      {"yellow rubber duck",    {{"yellow", "rubber duck", "bath toy", "toy"}, "rubber ducky"}},
      {"brown teddy bear",      {{"brown", "teddy bear", "stuffed animal", "toy"}, "plush bear"}},
      {"wooden toy block",      {{"wooden", "toy block", "building toy", "toy"}, "building block"}},
      {"pink piggy bank",       {{"pink", "piggy bank", "money box", "container"}, "coin bank"}},
      {"orange traffic cone",   {{"orange", "traffic cone", "road marker", "safety equipment"}, "safety cone"}},
      {"red fire extinguisher", {{"red", "fire extinguisher", "firefighting equipment", "safety equipment"}, "extinguisher"}},
      {"black camera",          {{"black", "camera", "camera equipment", "electronics"}, "digital camera"}},
      {"cyan water bottle",     {{"cyan", "water bottle", "bottle", "container"}, "drink bottle"}},
      {"silver tin can",        {{"silver", "tin can", "can", "container"}, "soda can"}},
      {"teal flower pot",       {{"teal", "flower pot", "planter", "container"}, "plant pot"}},
      {"golden ring",           {{"golden", "ring", "jewelry", "accessory"}, "gold band"}},
      {"magenta party hat",     {{"magenta", "party hat", "hat", "clothing"}, "birthday hat"}},
      {"navy backpack",         {{"navy", "backpack", "bag", "accessory"}, "rucksack"}},
      {"lime tennis ball",      {{"lime", "tennis ball", "ball", "sports equipment"}, "fuzzy ball"}},
      {"orange basketball",     {{"orange", "basketball", "ball", "sports equipment"}, "hoop ball"}},
      {"grey stone",            {{"grey", "stone", "rock", "natural object"}, "pebble"}},
      {"yellow sponge",         {{"yellow", "sponge", "cleaning supply", "household item"}, "scrub sponge"}},
      // background surfaces ("stuff"): what 3D-OVS labels and a user may ask for
      {"wooden table",          {{"wooden", "table", "furniture", "furniture"}, "desk"}},
      {"shelf",                 {{"", "shelf", "furniture", "furniture"}, "bookcase"}},
      {"floor",                 {{"", "floor", "ground surface", "room surface"}, "flooring"}},
      {"wall",                  {{"", "wall", "wall surface", "room surface"}, "partition"}},
      {"sky",                   {{"", "sky", "", ""}, ""}},
  };
  return m;
}
// clang-format on

std::vector<double> attribute_vector(const std::string& a, int dim) {
  const std::string fam = colour_family(a);
  if (fam.empty()) return word(a, dim);
  std::vector<double> v(dim, 0.0);
  add(v, word(fam, dim), 0.6);
  add(v, word(a, dim), 0.8);
  return normalised(v);
}

std::vector<double> noun_vector(const Lexeme& x, int dim) {
  std::vector<double> v(dim, 0.0);
  if (!x.group.empty()) add(v, word(x.group, dim), 0.35);
  if (!x.category.empty()) add(v, word(x.category, dim), 0.55);
  if (!x.noun.empty()) add(v, word(x.noun, dim), x.category.empty() ? 1.0 : 0.76);
  return normalised(v);
}

std::vector<double> content(const Lexeme& x, int dim) {
  std::vector<double> v(dim, 0.0);
  const bool noun = !x.noun.empty() || !x.category.empty() || !x.group.empty();
  if (noun) add(v, noun_vector(x, dim), x.attribute.empty() ? 1.0 : kNounWeight);
  if (!x.attribute.empty()) add(v, attribute_vector(x.attribute, dim), noun ? kAttrWeight : 1.0);
  return normalised(v);
}

}  // namespace

std::string colour_family(const std::string& a) {
  static const std::map<std::string, std::string> f = {{"lime", "green"},    {"navy", "blue"},    {"teal", "cyan"},
                                                       {"golden", "yellow"}, {"magenta", "pink"}, {"silver", "grey"}};
  auto it = f.find(a);
  return it == f.end() ? "" : it->second;
}

Lexeme lexeme_of(const std::string& name) {
  auto it = lexicon().find(name);
  if (it == lexicon().end()) fail("synth: no lexicon entry for '{}' (src/synth/language.cpp)", name);
  return it->second.x;
}

bool in_lexicon(const std::string& name) { return lexicon().count(name) > 0; }

std::string synonym_of(const std::string& name) {
  auto it = lexicon().find(name);
  return it == lexicon().end() ? std::string() : it->second.synonym;
}

std::string attribute_phrase(const Lexeme& x) { return x.attribute.empty() ? "" : "the " + x.attribute + " one"; }

std::vector<float> text_direction(int dim) { return to_float(word("modality:text", dim)); }

std::vector<float> image_direction(int dim) {
  std::vector<double> v(dim, 0.0);
  add(v, word("modality:text", dim), kGap);
  add(v, word("modality:image", dim), std::sqrt(1 - kGap * kGap));
  return to_float(normalised(v));
}

std::vector<float> text_embedding(const Lexeme& x, int dim, const std::string& extra_word) {
  std::vector<double> c = content(x, dim);
  if (!extra_word.empty()) {
    add(c, word(extra_word, dim), 0.45);
    c = normalised(c);
  }
  std::vector<double> v(dim, 0.0);
  add(v, word("modality:text", dim), kTextShared);
  add(v, c, 1.0);
  return to_float(normalised(v));
}

std::vector<float> generic_text_embedding(const std::string& phrase, int dim) {
  std::vector<double> v(dim, 0.0);
  add(v, word("modality:text", dim), kTextShared);
  add(v, word(phrase, dim), 1.0);
  return to_float(normalised(v));
}

std::vector<float> image_content(const Lexeme& x, int dim) {
  if (x.noun.empty() || x.noun == "sky") return std::vector<float>(dim, 0.f);
  return to_float(content(x, dim));
}

}  // namespace hgs::synth
