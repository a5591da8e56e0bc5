// The two evaluation protocols on per-pixel relevancy maps.
//
// LERF-OVS (LangSplat's evaluate_iou_loc.py, re-implemented):
//   smoothed  v' = 0.5 * (box_k(v) + v)               box_k: filters.h box_filter, k = 30
//   n         = (v' - min v') / (max v' - min v' + 1e-9)
//   out       = clip(2 n - 1, 0, 1)
//   mask      = majority_7x7(out > 0.4)
//   IoU / boundary IoU / pixel accuracy of the mask against the category's ground truth.
//   Localisation: the argmax of box_k(v) (the box filter alone) is a hit when it lies in any of the category's
//   ground-truth boxes (pixel centre in the closed box); with tied maxima, any tied pixel may hit (as LangSplat).
//   A constant map gives n = 0 everywhere, hence an empty mask.
//   The queries of a frame are the categories of its label file (LangSplat sets the positives to them), the
//   relevancy map is LERF's (query/relevancy.h) at the label resolution; scene mIoU = mean over (frame, query).
//   LangSplat picks, per query, the best of 3 SAM-level feature maps by the max of v'; with one map per query
//   that choice does not arise.
//
// 3D-OVS (the 3D-OVS paper's evaluation, re-implemented): per pixel the class with the largest relevancy
//   (no background class; ties go to the lower class index), per image and class IoU with classes absent
//   from both prediction and ground truth scoring 0 (sklearn's jaccard_score zero_division), image mIoU =
//   mean over all classes; accuracy = fraction of pixels whose ground-truth class vector is exactly the
//   one-hot of the predicted class (sklearn's accuracy_score on the multi-label indicator matrices), so
//   unlabelled pixels and pixels in several class masks count as errors. Boundary IoU per class uses the
//   same pairs and the same absent-in-both = 0 rule.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "eval/labels.h"
#include "eval/metrics.h"

namespace hgs::eval {

struct LerfOptions {
  int box = 30;            // box filter window (smoothing and localisation)
  float threshold = 0.4f;  // on out = clip(2n - 1, 0, 1)
  int majority = 7;        // majority filter window (odd); <= 1 disables it
  int boundary_d = 0;      // boundary IoU width; <= 0: Cheng et al.'s d from the image size
};

// LangSplat's windows were set on LERF-OVS frames about this wide.
constexpr int kLerfReferenceWidth = 1000;
// The box and majority windows scaled to an image `width` pixels wide (x width / kLerfReferenceWidth): the box
// rounded, at least 1; the majority window the odd number at or below its scaled size (<= 1: no majority filter).
// At 1000 px they are LangSplat's (30, 7); at 160 px (5, 1); at 320 px (10, 1).
LerfOptions scaled_lerf_options(int width, const LerfOptions& base = {});

struct LerfPost {
  std::vector<float> boxed;       // [H, W] box_k(v)
  std::vector<float> smoothed;    // [H, W] 0.5 (box_k(v) + v)
  std::vector<float> activation;  // [H, W] clip(2n - 1, 0, 1)
  Mask raw_mask;                  // [H, W] activation > threshold
  Mask mask;                      // [H, W] after the majority filter
};
LerfPost lerf_postprocess(const std::vector<float>& relevancy, int width, int height,  // [H, W]
                          const LerfOptions& opt = {});

struct Localisation {
  int x = -1, y = -1;  // the first tied maximum of box_k(v) inside a box if any hits, else the first in raster order
  float score = 0;     // box_k(v) there
  bool hit = false;
};
// `boxed` is box_k(v) ([H, W]), e.g. LerfPost::boxed.
Localisation lerf_localise(const std::vector<float>& boxed, int width, int height, const std::vector<BBox>& bboxes);

struct LerfQueryResult {
  MaskScores scores;
  Localisation loc;
  LerfPost post;
};
// The whole per-(frame, query) protocol for one relevancy map against one category.
LerfQueryResult evaluate_lerf_query(const std::vector<float>& relevancy, int width, int height,  // [H, W]
                                    const LerfCategory& gt, const LerfOptions& opt = {});

struct OvsImageResult {
  std::vector<uint16_t> prediction;  // [H, W] class index per pixel
  std::vector<double> iou, biou;     // [C]; NaN for a class not scored (labelled-only scoring, class absent)
  double miou = 0, mbiou = 0, accuracy = 0;
  double ceiling = 0;  // the highest mIoU any argmax prediction can score on this frame (ovs_ceiling)
};
// How a 3D-OVS frame is scored. Protocol: as 3D-OVS's own evaluation (sklearn's jaccard_score per class on the
// argmax, zero_division = 0): every pixel counts, a class absent from the frame scores 0. LabelledOnly: only the
// pixels the ground truth gives a class are scored (the others are void, as VOC's and Cityscapes' ignore label)
// and a class absent from the frame is not scored (as LERF-OVS and the instances protocol leave out what a view
// does not show). On 3D-OVS's own scenes, where the classes cover every pixel and every class is in view, the
// two agree; on a scene that shows the sky or leaves classes out of some views they do not (docs/ablation.md).
enum class OvsScoring { Protocol, LabelledOnly };
// The best mIoU an argmax prediction (one class at every pixel) can score on a frame under the protocol: the
// ground truth on its labelled pixels and every unlabelled pixel (V of them) given to one class; to a class absent
// from the frame (scoring 0 anyway) if there is one, else to the largest class (IoU G / (G + V): the loss
// V / (G + V) is concave in V, so no split of the unlabelled pixels loses less). Masks assumed disjoint.
// LabelledOnly: 1.
double ovs_ceiling(const std::vector<Mask>& gt, OvsScoring scoring = OvsScoring::Protocol);
// Per-pixel argmax over class relevancy maps (`relevancy[c]` is [H, W], C >= 1) -> class index map [H, W].
std::vector<uint16_t> argmax_classes(const std::vector<std::vector<float>>& relevancy, int width, int height);
// 3D-OVS metrics of a predicted class map against the class masks (`gt[c]` [H, W], same C as classes).
OvsImageResult evaluate_3dovs_prediction(const std::vector<uint16_t>& prediction, const std::vector<Mask>& gt,
                                         int width, int height, int boundary_d = 0,
                                         OvsScoring scoring = OvsScoring::Protocol);
// argmax_classes + evaluate_3dovs_prediction.
OvsImageResult evaluate_3dovs_image(const std::vector<std::vector<float>>& relevancy, const std::vector<Mask>& gt,
                                    int width, int height, int boundary_d = 0,
                                    OvsScoring scoring = OvsScoring::Protocol);

}  // namespace hgs::eval
