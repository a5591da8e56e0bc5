// masks/objects.json (object id -> name): `hgs train|eval|view SCENE` -> load_scene (Scene::object_names) and
// `hgs eval` on synthetic scenes -> eval::load_object_names.
#include "core/error.h"
#include "eval/instances.h"
#include "fuzz.h"
#include "scene/scene.h"

HGS_FUZZ_TARGET(objects_json) {
  static const auto scene = hgs::fuzz::scene_skeleton("objects_json");
  hgs::fuzz::put_file(scene / "masks" / "objects.json", {reinterpret_cast<const char*>(data), size});
  try {
    hgs::load_scene(scene);
  } catch (const hgs::Error&) {
  }
  try {
    hgs::eval::load_object_names(scene);
  } catch (const hgs::Error&) {
  }
  return 0;
}
