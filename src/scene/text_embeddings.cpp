// Phrase files and the text_embeddings.json writer (see text_embeddings.h).
#include "scene/text_embeddings.h"

#include "core/fs.h"

namespace hgs {

std::vector<std::string> read_phrase_file(const std::filesystem::path& file) {
  std::vector<std::string> out;
  const std::string body = read_file_text(file);
  for (size_t pos = 0; pos <= body.size();) {
    size_t e = body.find('\n', pos);
    if (e == std::string::npos) e = body.size();
    std::string line = body.substr(pos, e - pos);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!line.empty()) out.push_back(line);
    pos = e + 1;
  }
  return out;
}

void add_text_embeddings(nlohmann::json& te, const std::vector<std::string>& phrases,
                         const std::vector<float>& embeddings, int dim) {
  for (size_t i = 0; i < phrases.size(); ++i)
    te[phrases[i]] = std::vector<float>(embeddings.begin() + i * dim, embeddings.begin() + (i + 1) * dim);
}

void write_text_embeddings(const std::filesystem::path& file, const nlohmann::json& te) {
  atomic_write_text(file, te.dump() + "\n");
}

}  // namespace hgs
