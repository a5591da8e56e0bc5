// SAM's automatic mask generator (segment-anything's SamAutomaticMaskGenerator with one crop, the whole image):
// a regular grid of n x n foreground points (cell centres), decoded in batches with all three multimask outputs;
// masks are kept when their predicted IoU exceeds pred_iou_thresh and their stability score (pixels above
// +offset over pixels above -offset of the full-resolution logits) exceeds stability_score_thresh; the rest
// are binarised at 0, boxed, and reduced by greedy box NMS (IoU > box_nms_thresh suppressed, highest
// predicted IoU first). Output order: descending predicted IoU. With min_mask_region_area, small holes and
// islands are then removed and NMS runs again with the unchanged masks first.
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "sam/model.h"

namespace hgs::sam {

struct AmgOptions {  // segment-anything's defaults
  int points_per_side = 32;
  int points_per_batch = 64;
  float pred_iou_thresh = 0.88f;
  float stability_score_thresh = 0.95f;
  float stability_score_offset = 1.0f;
  float box_nms_thresh = 0.7f;
  // > 0: fill holes and drop islands smaller than this many pixels in every mask (8-connected regions), then
  // NMS again preferring the masks that did not change (segment-anything's postprocess_small_regions).
  int min_mask_region_area = 0;
};

struct AmgMask {
  std::vector<uint8_t> mask;  // [H, W] 0/1 at the original image size
  int area = 0;
  std::array<int, 4> bbox{};  // x, y, w, h (segment-anything's XYWH: w = x1 - x0 of inclusive bounds)
  float predicted_iou = 0, stability_score = 0;
  std::array<float, 2> point{};  // the prompt point, original pixels
};

// Grid points in [0, 1]^2: ((i + 0.5) / n, (j + 0.5) / n), x fastest: [n * n] of (x, y).
std::vector<std::array<float, 2>> point_grid(int n);

// Fraction of pixels above thr + offset among those above thr - offset, logits [n]; 0 when none is above.
float stability_score(const float* logits, size_t n, float thr, float offset);

// Greedy NMS over boxes (x0, y0, x1, y1) by descending score: returns kept indices in that order.
std::vector<int> box_nms(const std::vector<std::array<float, 4>>& boxes, const std::vector<float>& scores,
                         float thresh);

// Fills (holes = true: regions of 0s) or removes (false: regions of 1s) the 8-connected regions of mask [H, W]
// smaller than `area` pixels; when every region of 1s is small, the largest is kept. Returns whether the mask
// changed.
bool remove_small_regions(std::vector<uint8_t>& mask, int W, int H, int area, bool holes);

// `progress(done, total)` is called after every batch of points when given.
std::vector<AmgMask> generate_masks(const SamModel& m, const ImageEmbedding& e, const AmgOptions& o = {},
                                    const std::function<void(int, int)>& progress = {});

}  // namespace hgs::sam
