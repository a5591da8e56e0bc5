// NPY arrays: `hgs train|eval|features` reading SCENE/features/<stem>.npy and masks/<stem>.conf.npy ->
// Scene::load_feature_grid / load_confidence -> read_npy (+ NpyArray::to_float), and read_npy_header.
#include "core/error.h"
#include "core/npy.h"
#include "fuzz.h"

HGS_FUZZ_TARGET(npy) {
  static const auto dir = hgs::fuzz::scratch("npy");
  const auto file = dir / "array.npy";
  hgs::fuzz::put_file(file, {reinterpret_cast<const char*>(data), size});
  try {
    hgs::read_npy_header(file);
    const hgs::NpyArray a = hgs::read_npy(file);
    std::vector<float> f = a.to_float();
    if (f.size() != a.size()) __builtin_trap();
  } catch (const hgs::Error&) {
  }
  return 0;
}
