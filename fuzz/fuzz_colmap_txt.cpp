// COLMAP text model: `hgs train|info|... SCENE` -> load_scene -> read_colmap -> read_colmap_txt on
// SCENE/sparse/0/{cameras,images,points3D}.txt. Input: the three files joined by fuzz::kSplit.
#include "colmap_scene.h"

HGS_FUZZ_TARGET(colmap_txt) { return hgs::fuzz::colmap_scene(data, size, ".txt"); }
