// `hgs embed-text --clip W --text "..." [--text ...] --out FILE.json`: CLIP text embeddings in the
// text_embeddings.json format {"phrase": [D floats], ...} (L2-normalised).
#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "cli/command.h"
#include "clip/model.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/json_file.h"
#include "nn/thread_pool.h"
#include "scene/text_embeddings.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct EmbedTextArgs {
  std::string clip, out, text_file, act = "auto";
  std::vector<std::string> texts;
  bool canonical = false, merge = false;
  int threads = 0;
};

void run_embed_text(const EmbedTextArgs& a) {
  nn::set_num_threads(a.threads);
  std::vector<std::string> phrases = a.texts;
  if (!a.text_file.empty())
    for (const std::string& p : read_phrase_file(a.text_file)) phrases.push_back(p);
  if (a.canonical)
    for (const char* c : kCanonicalPhrases) phrases.push_back(c);
  if (phrases.empty()) fail("embed-text: no phrases (use --text, --text-file or --canonical)");
  nlohmann::json out = nlohmann::json::object();
  if (a.merge && fs::exists(a.out)) {
    try {
      out = read_json_file(a.out);
    } catch (const Error& e) {
      fail("{} (cannot --merge into it)", e.what());
    }
    if (!out.is_object()) fail("{}: not a JSON object of phrases (cannot --merge into it)", a.out);
  }
  clip::ClipOptions opt;
  opt.activation = clip::parse_activation(a.act);
  clip::ClipModel m = clip::ClipModel::load(a.clip, opt);
  if (!m.has_text) fail("{}: the model has no text tower", a.clip);
  fmt::print(stderr, "model: {}\n", m.describe());
  if (a.merge && !out.empty()) {
    auto first = out.begin();
    if (first->is_array() && int(first->size()) != m.embed_dim)
      fail("{}: holds {}-dimensional embeddings but the model gives {}", a.out, first->size(), m.embed_dim);
  }
  std::vector<float> e = m.embed_text(phrases);
  add_text_embeddings(out, phrases, e, m.embed_dim);
  write_text_embeddings(a.out, out);
  fmt::print("wrote {} phrases (D = {}) to {}\n", phrases.size(), m.embed_dim, a.out);
}

CommandRegistration reg(
    {"embed-text", "Embed text phrases with a CLIP model (safetensors) into text_embeddings.json", 20,
     [](CLI::App& sub) {
       auto a = std::make_shared<EmbedTextArgs>();
       sub.add_option("--clip", a->clip, "CLIP weights (.safetensors, open_clip or Hugging Face naming)")
           ->required()
           ->check(CLI::ExistingFile);
       sub.add_option("--text", a->texts, "A phrase to embed (repeatable)");
       sub.add_option("--text-file", a->text_file, "File with one phrase per line")->check(CLI::ExistingFile);
       sub.add_flag("--canonical", a->canonical,
                    "Also embed LERF's canonical phrases (object, things, stuff, texture)");
       sub.add_option("--out", a->out, "Output JSON {\"phrase\": [D floats]}")->required();
       sub.add_flag("--merge", a->merge, "Keep the phrases already in --out (replacing those embedded again)");
       sub.add_option(
              "--act", a->act,
              "Activation: auto (config file, else GELU for open_clip / QuickGELU for HF naming), gelu, quick_gelu")
           ->capture_default_str();
       add_threads_option(sub, a->threads);
       return [a] { run_embed_text(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
