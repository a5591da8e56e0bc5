// Text embeddings for queries: from the scene's text_embeddings.json, or computed by a user-supplied CLIP
// model (--clip FILE, src/clip). Embeddings are L2-normalised and cached per phrase.
#pragma once
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace hgs::clip {
class ClipModel;
}

namespace hgs::query {

class TextEmbedder {
 public:
  // clip_path empty: only the scene's text_embeddings.json is used.
  TextEmbedder(const Scene& scene, const std::filesystem::path& clip_path);
  ~TextEmbedder();
  TextEmbedder(TextEmbedder&&) noexcept;
  // Unit embedding [D]; fails with a clear message for a phrase that is neither in the scene's
  // text_embeddings.json nor computable (no --clip).
  const std::vector<float>& embed(const std::string& phrase);
  // The canonical phrases "object", "things", "stuff", "texture".
  std::vector<std::vector<float>> canonical();
  int dim() const { return dim_; }
  std::string source() const;

 private:
  std::map<std::string, std::vector<float>> cache_;
  std::unique_ptr<clip::ClipModel> clip_;
  std::filesystem::path scene_file_;
  int dim_ = 0;
};

}  // namespace hgs::query
