// safetensors (header JSON + tensor table, F32/F16/BF16 data): `hgs embed-text|features|query --clip FILE` ->
// ClipModel::load -> SafeTensors; here SafeTensors itself (every tensor converted by to_float, as the loader
// does) and ClipModel::load on the same file.
#include "clip/model.h"
#include "core/error.h"
#include "fuzz.h"
#include "nn/safetensors.h"

HGS_FUZZ_TARGET(safetensors) {
  static const auto dir = hgs::fuzz::scratch("safetensors");
  const auto file = dir / "model.safetensors";
  hgs::fuzz::put_file(file, {reinterpret_cast<const char*>(data), size});
  try {
    const hgs::nn::SafeTensors st(file);
    for (const std::string& name : st.names()) {
      const hgs::nn::TensorInfo& t = st.info(name);
      try {
        st.check_shape(name, std::vector<int64_t>(t.shape.size(), -1));
        if (st.to_float(name).size() != t.numel()) __builtin_trap();
      } catch (const hgs::Error&) {
      }
    }
  } catch (const hgs::Error&) {
  }
  try {
    hgs::clip::ClipModel::load(file);
  } catch (const hgs::Error&) {
  }
  return 0;
}
