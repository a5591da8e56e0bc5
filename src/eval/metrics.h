// Segmentation metrics on binary masks: IoU, pixel accuracy and boundary IoU (Cheng et al., CVPR 2021), plus
// the binary morphology they need. A mask is a std::vector<uint8_t> of shape [H, W], row-major; any non-zero
// value counts as inside. Every function takes the size as (width, height) and checks the vector lengths.
//
// Conventions for empty masks (documented here once, used everywhere in src/eval):
//  - iou(G, P) with G and P both empty is 1 (the prediction agrees perfectly with "nothing there"); with exactly
//    one of them empty it is 0. The 3D-OVS protocol overrides the both-empty case to 0 (protocols.h), this
//    function does not.
//  - boundary_iou with both boundaries empty is NaN, as the reference (boundary-iou-api divides 0 by 0); report
//    means skip NaN (report.cpp), so such a pair counts in no boundary mean. One empty => 0.
//  - pixel_accuracy of two empty masks is 1 (every pixel agrees). A 0 x 0 image is an error.
#pragma once
#include <cstdint>
#include <vector>

namespace hgs::eval {

using Mask = std::vector<uint8_t>;  // [H, W], 0 = outside, non-zero = inside

// Counts of a (ground truth, prediction) pair.
struct Confusion {
  long tp = 0, fp = 0, fn = 0, tn = 0;
};
Confusion confusion(const Mask& gt, const Mask& pred, int width, int height);  // gt, pred: [H, W]

double iou(const Mask& gt, const Mask& pred, int width, int height);             // [H, W] each
double pixel_accuracy(const Mask& gt, const Mask& pred, int width, int height);  // [H, W] each

// Boundary dilation width of Cheng et al.: d = max(1, round(0.02 * sqrt(H^2 + W^2))), rounding halves to even
// as Python's round() in their reference code does (100 x 75: 0.02 * 125 = 2.5 -> 2).
int boundary_width(int width, int height);

// Binary erosion by a 3x3 square, applied `iterations` times. Pixels outside the image count as
// `outside_value` (0: the mask is padded with zeros, so it erodes from the image border too; 1: the border
// does not erode it). Returns a 0/1 mask.
Mask erode3x3(const Mask& m, int width, int height, int iterations, uint8_t outside_value = 0);  // [H, W]

// Boundary region of Cheng et al.: M minus the erosion of M (padded with zeros) by a 3x3 element d times,
// i.e. the inside pixels whose Chebyshev distance to the nearest outside pixel (image exterior included) is
// at most d. Returns a 0/1 mask.
Mask boundary_region(const Mask& m, int width, int height, int d);  // [H, W]

// Boundary IoU = |B(G) ∩ B(P)| / |B(G) ∪ B(P)| with B = boundary_region(., d). d <= 0 means
// d = boundary_width(width, height).
double boundary_iou(const Mask& gt, const Mask& pred, int width, int height, int d = 0);

// The three numbers reported per (frame, query).
struct MaskScores {
  double iou = 0, biou = 0, acc = 0;
};
MaskScores score_mask(const Mask& gt, const Mask& pred, int width, int height, int d = 0);

}  // namespace hgs::eval
