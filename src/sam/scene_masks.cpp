// SAM JSON files of every view (see scene_masks.h).
#include "sam/scene_masks.h"

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "core/progress.h"
#include "masks/rle.h"

namespace hgs::sam {
namespace fs = std::filesystem;
namespace {

// One view's masks in segment-anything's JSON layout, the whole image as the crop box.
nlohmann::json sam_json(const std::vector<AmgMask>& ms, int w, int h) {
  nlohmann::json list = nlohmann::json::array();
  for (const AmgMask& m : ms) {
    masks::Rle r = masks::rle_encode(m.mask, w, h);
    list.push_back({{"segmentation", {{"size", {h, w}}, {"counts", masks::rle_counts_to_string(r.counts)}}},
                    {"area", m.area},
                    {"bbox", {m.bbox[0], m.bbox[1], m.bbox[2], m.bbox[3]}},
                    {"predicted_iou", m.predicted_iou},
                    {"point_coords", {{m.point[0], m.point[1]}}},
                    {"stability_score", m.stability_score},
                    {"crop_box", {0, 0, w, h}}});
  }
  return list;
}

}  // namespace

SceneMasksSummary write_sam_files(const Scene& s, const SamModel& m, const AmgOptions& amg, const fs::path& out_dir,
                                  bool force, bool progress) {
  const int n = amg.points_per_side * amg.points_per_side;
  const int batches = (n + amg.points_per_batch - 1) / amg.points_per_batch;
  Progress bar("sam masks", long(s.views.size()) * batches, progress);
  SceneMasksSummary r;
  int done = 0;
  for (const View& v : s.views) {
    const fs::path out = out_dir / (v.stem + ".json");
    if (!force && fs::exists(out)) {
      ++r.skipped;
    } else {
      Image img = s.load_image(v.index);
      ImageEmbedding e = m.embed(img);
      std::vector<AmgMask> ms = generate_masks(m, e, amg, [&](int d, int) {
        bar.update(long(done) * batches + (d + amg.points_per_batch - 1) / amg.points_per_batch, v.stem);
      });
      ensure_dir(out.parent_path());
      atomic_write_text(out, sam_json(ms, img.width, img.height).dump());
      r.masks += ms.size();
      ++r.written;
    }
    ++done;
    bar.update(long(done) * batches, fmt::format("{} masks", r.masks));
  }
  bar.finish(fmt::format("{} masks", r.masks));
  return r;
}

}  // namespace hgs::sam
