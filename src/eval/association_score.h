// Association quality against a synthetic scene's truth (gt/instances): global mask ids are matched one to one
// to true objects, greedily on the sum over views of their per-view IoU (largest first; ties: smaller ids), then
// every (view, object) pair where the object covers at least `min_pixels` of gt/instances scores the IoU of its
// matched id's mask against it (0 when unmatched or absent) and its boundary IoU (eval/metrics.h, the band the
// evaluation uses: 2 % of the diagonal). Used by `hgs masks score` for docs/association.md and docs/ablation.md.
#pragma once
#include <filesystem>
#include <map>
#include <vector>

namespace hgs::eval {

struct AssociationScore {
  int views = 0;                     // views with both a mask and a gt instance map
  int pairs = 0;                     // (view, object) pairs scored
  double mean_iou = 0;               // mean over the pairs
  double object_mean_iou = 0;        // mean over objects of their mean over views
  double pairs_above_half = 0;       // fraction of pairs with IoU >= 0.5
  double mean_biou = 0;              // mean boundary IoU over the pairs
  double found_mean_biou = 0;        // the same over the pairs with IoU >= 0.5 (the mask found the object)
  std::map<int, int> match;          // true object -> mask id (objects without a match absent)
  std::map<int, double> object_iou;  // true object -> mean IoU over its views
};

// `masks_dir` holds <stem>.png label maps of the scene's views (default: SCENE/masks); test_only: the scene's test
// views alone (those the evaluation scores a model on).
AssociationScore score_association(const std::filesystem::path& scene, const std::filesystem::path& masks_dir,
                                   int min_pixels = 16, bool test_only = false);

}  // namespace hgs::eval
