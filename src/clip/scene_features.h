// Dense CLIP features of every view of a scene -> SCENE/features/<stem>.npy, float16 [h, w, D] (what `Scene`
// reads), for `hgs features` and `hgs prepare`. Each file is written atomically and a view whose file exists is
// skipped unless `force`, so an interrupted run resumes.
#pragma once
#include "clip/model.h"
#include "scene/scene.h"

namespace hgs::clip {

struct SceneFeaturesSummary {
  int written = 0, skipped = 0;  // views
  int grid_w = 0, grid_h = 0;    // of the last file written
};

SceneFeaturesSummary write_clip_features(const Scene& scene, const ClipModel& model, const DenseOptions& d, bool force,
                                         bool progress);

}  // namespace hgs::clip
