// COLMAP binary model: `hgs train|info|... SCENE` -> load_scene -> read_colmap -> read_colmap_bin on
// SCENE/sparse/0/{cameras,images,points3D}.bin. Input: the three files joined by fuzz::kSplit.
#include "colmap_scene.h"

HGS_FUZZ_TARGET(colmap_bin) { return hgs::fuzz::colmap_scene(data, size, ".bin"); }
