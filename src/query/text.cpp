#include "query/text.h"

#include <cmath>

#include "clip/model.h"
#include "core/error.h"
#include "core/excerpt.h"
#include "query/query.h"
#include "scene/text_embeddings.h"

namespace hgs::query {

TextEmbedder::TextEmbedder(const Scene& scene, const std::filesystem::path& clip_path)
    : scene_file_(scene.root / "text_embeddings.json") {
  if (!clip_path.empty()) {
    clip_ = std::make_unique<clip::ClipModel>(clip::ClipModel::load(clip_path));
    dim_ = clip_->embed_dim;
  } else {
    if (scene.text_embeddings.empty())
      fail("{}: no text embeddings in the scene; pass --clip FILE (OpenCLIP weights) to embed the query text",
           scene_file_.string());
    for (auto& [k, v] : scene.text_embeddings) {
      std::vector<float> u = v;
      double s = 0;
      for (float x : u) s += double(x) * x;
      const float inv = s > 0 ? float(1 / std::sqrt(s)) : 0.f;
      for (float& x : u) x *= inv;
      cache_[k] = std::move(u);
    }
    dim_ = static_cast<int>(cache_.begin()->second.size());
  }
}

TextEmbedder::~TextEmbedder() = default;
TextEmbedder::TextEmbedder(TextEmbedder&&) noexcept = default;

const std::vector<float>& TextEmbedder::embed(const std::string& phrase) {
  auto it = cache_.find(phrase);
  if (it != cache_.end()) return it->second;
  if (!clip_)
    fail("{}: no embedding for \"{}\" (known phrases only without --clip; see `hgs info`)", scene_file_.string(),
         excerpt(phrase));
  auto e = clip_->embed_text({phrase});
  return cache_[phrase] = std::move(e);
}

std::vector<std::vector<float>> TextEmbedder::canonical() {
  std::vector<std::vector<float>> c;
  for (const char* p : kCanonicalPhrases) c.push_back(embed(p));
  return c;
}

std::string TextEmbedder::source() const { return clip_ ? std::string("CLIP text encoder") : scene_file_.string(); }

}  // namespace hgs::query
