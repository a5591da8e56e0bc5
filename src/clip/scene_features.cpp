// CLIP feature files of every view (see scene_features.h).
#include "clip/scene_features.h"

#include <fmt/format.h>

#include "core/fs.h"
#include "core/npy.h"
#include "core/progress.h"

namespace hgs::clip {
namespace fs = std::filesystem;

SceneFeaturesSummary write_clip_features(const Scene& s, const ClipModel& m, const DenseOptions& d, bool force,
                                         bool progress) {
  const fs::path out_dir = s.root / "features";
  Progress bar("clip features", long(s.views.size()), progress);
  SceneFeaturesSummary r;
  int done = 0;
  for (const View& v : s.views) {
    const fs::path out = out_dir / (v.stem + ".npy");
    if (!force && fs::exists(out)) {
      ++r.skipped;
    } else {
      Image img = s.load_image(v.index);
      DenseFeatures f = m.dense_features(img, d);
      ensure_dir(out.parent_path());
      write_npy(out, make_npy_f16({size_t(f.h), size_t(f.w), size_t(f.dim)}, f.data.data()));
      r.grid_w = f.w, r.grid_h = f.h;
      ++r.written;
    }
    bar.update(++done, r.grid_h ? fmt::format("{}x{} grid", r.grid_w, r.grid_h) : "");
  }
  bar.finish();
  return r;
}

}  // namespace hgs::clip
