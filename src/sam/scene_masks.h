// SAM's automatic masks of every view of a scene, one SAM JSON file per view (COCO RLE: what `hgs masks import
// --from sam-json` reads), for `hgs masks generate` and `hgs prepare`. Each file is written atomically and a view
// whose file exists is skipped unless `force`, so an interrupted run resumes.
#pragma once
#include <cstddef>
#include <filesystem>

#include "sam/amg.h"
#include "scene/scene.h"

namespace hgs::sam {

struct SceneMasksSummary {
  int written = 0, skipped = 0;  // views
  size_t masks = 0;              // in the files written
};

// out_dir/<stem>.json for every view of `scene`.
SceneMasksSummary write_sam_files(const Scene& scene, const SamModel& model, const AmgOptions& amg,
                                  const std::filesystem::path& out_dir, bool force, bool progress);

}  // namespace hgs::sam
