// Overlapping per-view masks (SAM gives whole objects and their parts) flattened into one label map.
//
// Rule (deterministic, documented in docs/formats.md): mask i gets id i + 1 (its position in the source list);
// each pixel takes the SMALLEST mask that covers it (fewest pixels), ties going to the mask listed first.
// Implemented by painting the masks in order of decreasing area (equal areas: later-listed first), so a part
// painted after its whole wins where they overlap. Smaller-wins keeps every part visible and a whole object
// where no part covers it; parts of one object are reunited later by `hgs masks associate`.
// Confidence of a pixel = the score of the mask that won it (1 where no mask covers it).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"
#include "masks/rle.h"

namespace hgs::masks {

struct SourceMask {
  Rle rle;                    // the mask itself (column-major runs, see rle.h)
  double predicted_iou = -1;  // SAM's scores when given (< 0 = absent)
  double stability_score = -1;
  std::string source;  // where it came from, e.g. "frame_00001.json[3]" or "frame_00001/3.png"
};

// Pixels inside (the sum of the 1-runs).
uint64_t rle_area(const Rle& r);
// Per-mask confidence zeta = clamp(predicted_iou, 0, 1) * clamp(stability_score, 0, 1), either alone when the
// other is absent, or -1 when neither is given.
double mask_confidence(const SourceMask& m);

struct Flattened {
  LabelMap labels;                // [H, W], 0 = no mask, i + 1 = source mask i
  std::vector<float> confidence;  // [H, W]; empty when no mask has a score
  std::vector<uint64_t> visible;  // [M] pixels each mask kept after flattening
};

// The hierarchy flattening hides: for every mask i, the smallest strictly larger mask j that holds at least
// `min_fraction` of i's pixels (i is a part of j), or -1. Sweep over the masks' runs in their common column-major
// order, keeping the set of masks that cover the current stretch, so the cost is in runs, not pixels.
std::vector<int> part_of(const std::vector<SourceMask>& masks, double min_fraction = 0.9);

// All masks must have size width x height (checked by the caller, which knows the file names).
Flattened flatten_masks(const std::vector<SourceMask>& masks, int width, int height);

}  // namespace hgs::masks
