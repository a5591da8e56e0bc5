// SCENE/text_embeddings.json ({"phrase": [D floats]}): `hgs query|eval|view SCENE` without --clip ->
// load_scene (Scene::text_embeddings) -> query::TextEmbedder, then one embed() per phrase.
#include "core/error.h"
#include "fuzz.h"
#include "query/text.h"
#include "scene/scene.h"

HGS_FUZZ_TARGET(text_embeddings_json) {
  static const auto scene = hgs::fuzz::scene_skeleton("text_embeddings_json");
  hgs::fuzz::put_file(scene / "text_embeddings.json", {reinterpret_cast<const char*>(data), size});
  try {
    const hgs::Scene s = hgs::load_scene(scene);
    hgs::query::TextEmbedder t(s, "");
    for (auto& [phrase, v] : s.text_embeddings)
      if (t.embed(phrase).size() != size_t(t.dim())) __builtin_trap();
  } catch (const hgs::Error&) {
  }
  return 0;
}
