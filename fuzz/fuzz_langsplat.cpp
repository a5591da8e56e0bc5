// LangSplat preprocessing output: `hgs masks import SCENE --from langsplat DIR` -> read_langsplat on
// <key>_s.npy ([4, h, w] mask indices, -1 = none) and <key>_f.npy ([M, D] features), every level, into a 32 x 24
// view at feature strides 1 and 4. Input: the _s.npy bytes, kSplit, the _f.npy bytes.
#include "core/error.h"
#include "fuzz.h"
#include "masks/sources.h"

HGS_FUZZ_TARGET(langsplat) {
  static const auto dir = hgs::fuzz::scratch("langsplat");
  const auto parts = hgs::fuzz::split(data, size, 2);
  const auto s_file = dir / "frame_00001_s.npy", f_file = dir / "frame_00001_f.npy";
  hgs::fuzz::put_file(s_file, parts[0]);
  hgs::fuzz::put_file(f_file, parts[1]);
  constexpr int W = 32, H = 24;
  for (int level = 0; level < 4; ++level)
    for (int stride : {1, 4}) {
      try {
        const auto v = hgs::masks::read_langsplat(s_file, f_file, level, W, H, stride);
        if (v.labels.width != W || v.labels.height != H) __builtin_trap();
        if (v.grid.size() != size_t(v.grid_h) * v.grid_w * v.dim) __builtin_trap();
      } catch (const hgs::Error&) {
      }
    }
  return 0;
}
