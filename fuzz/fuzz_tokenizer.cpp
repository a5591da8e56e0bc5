// CLIP tokenizer on arbitrary bytes (invalid UTF-8 included): `hgs embed-text`, `hgs query --clip TEXT` ->
// ClipModel::embed_text -> Tokenizer::shared().tokenize_padded (77 ids); also encode and a short context.
#include <string>

#include "clip/tokenizer.h"
#include "core/error.h"
#include "fuzz.h"

HGS_FUZZ_TARGET(tokenizer) {
  const hgs::clip::Tokenizer& tok = hgs::clip::Tokenizer::shared();
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const std::vector<int> ids = tok.tokenize_padded(text, 77);
    if (ids.size() != 77) __builtin_trap();
    for (int id : ids)
      if (id < 0 || id >= hgs::clip::Tokenizer::kVocab) __builtin_trap();
    for (int id : tok.encode(text))
      if (id < 0 || id >= hgs::clip::Tokenizer::kVocab) __builtin_trap();
    if (tok.tokenize(text, 5).size() > 5) __builtin_trap();
  } catch (const hgs::Error&) {
  }
  return 0;
}
