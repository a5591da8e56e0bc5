// Gaussian model PLY: `hgs render|query|eval|export|view --model FILE` -> read_model_ply.
#include "core/error.h"
#include "fuzz.h"
#include "model/ply.h"

HGS_FUZZ_TARGET(ply) {
  static const auto dir = hgs::fuzz::scratch("ply");
  hgs::fuzz::put_file(dir / "model.ply", {reinterpret_cast<const char*>(data), size});
  try {
    hgs::GaussianModel m = hgs::read_model_ply(dir / "model.ply");
    m.validate("fuzz");
  } catch (const hgs::Error&) {
  }
  return 0;
}
