// LERF-OVS label JSON (polygons, boxes): `hgs eval SCENE --protocol lerf` -> load_lerf_labels ->
// load_lerf_frame on SCENE/label/frame_00001.json, at full size and downscaled by 2.
#include "core/error.h"
#include "eval/labels.h"
#include "fuzz.h"

HGS_FUZZ_TARGET(lerf_labels) {
  static const auto scene = hgs::fuzz::scratch("lerf_labels");
  hgs::fuzz::put_file(scene / "label" / "frame_00001.json", {reinterpret_cast<const char*>(data), size});
  for (int downscale : {1, 2}) {
    try {
      hgs::eval::load_lerf_labels(scene, 0, 0, downscale);
    } catch (const hgs::Error&) {
    }
  }
  return 0;
}
