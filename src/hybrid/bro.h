// Boundary Reconstruction Optimization (paper eqs. 11-14).
//
// For one view u and object k:
//   B^pred = D(A^pred) - E(A^pred),  B^gt = D(M) - E(M),  B = clip(B^pred + B^gt, 0, 1)      (eqs. 12-13)
// with D / E the grey-scale dilation / erosion (max / min filter) by an s x s square (default 5; pixels
// outside the image are ignored). The forward differences are Dx I(x, y) = I(x+1, y) - I(x, y) and
// Dy I(x, y) = I(x, y+1) - I(x, y); their weights are the band over each difference's support:
// W^x(x, y) = max(B(x, y), B(x+1, y)), W^y(x, y) = max(B(x, y), B(x, y+1)). Then              (eq. 14)
//   L = sum_d || W^d (Dd I^pred - Dd I^gt) ||_1 / (C sum_d ||W^d||_1 + eps).
// B is treated as a constant: no gradient flows through the morphology or into A^pred (the band only
// selects where the loss looks), so the gradient goes to I^pred alone.
//
// Scale-invariant gradient (HybridConfig::bro_scale_invariant, on by default; see docs/results.md). Eq. 14 is an
// L1 on finite differences. Where the view's mask edge and the rendered edge do not coincide (SAM2-style masks
// jitter by a few pixels, swap or merge ids, miss objects, and eq. 2 drops their low-confidence rim), every
// misaligned pair of edges costs |edge_pred| + |edge_gt|, so lowering the whole object render lowers the loss:
// on noisy masks eq. 14 decreases monotonically as I^pred_{u,k} is scaled towards 0 (measured on a trained
// model: scaling every q_{n,k} by 0.5 lowers eq. 14 for 9 of 10 objects, for most by several times what it
// raises eq. 6), and since eq. 14 is normalised by the band (not the image, as eq. 6 is) that pull dominates for
// small objects.
// Trained this way objects fade below the mask threshold (the view logits learn to favour views whose masks
// miss them). We therefore take the gradient of eq. 14 at the render rescaled to a fixed norm,
//   L_bro( p * sg(||p||) / ||p|| ),  p = I^pred_{u,k} [H, W, C] as one vector, sg = stop-gradient,
// whose value is eq. 14 unchanged and whose gradient is g - (<g, p> / <p, p>) p (g = eq. 14's gradient): BRO
// may move and sharpen the object's edges but cannot make the object as a whole fainter or brighter.
//
// Scale rule (HybridConfig::bro_image_norm, on by default). Eq. 14 is a mean over its band; eq. 6 a mean over the
// image. With equal lambdas a band pixel then weighs HW / |band| times an image pixel of eq. 6 (20-50x for the
// objects of a 160x120 view, growing with resolution and shrinking objects), and on noisy masks the rim of every
// object is pulled down harder than eq. 6 and the RGB loss hold it (an object has no Gaussians outside its edge
// to raise, so removing a misaligned edge can only lower its rim). We weight each (u, k) term by its band's share
// of the image, sum_d ||W^d||_1 / (2 H W): BRO becomes, like eq. 6, a mean over the image, the same at every
// resolution. Measured in docs/results.md (without the rule: the full row falls below the no-BRO row).
#pragma once
#include <cstddef>
#include <functional>
#include <vector>

namespace hgs::hybrid {

// Grey-scale dilation (max filter) and erosion (min filter) with an s x s square, separable.
// in, out: [H, W]
void dilate(const float* in, int H, int W, int s, float* out);
void erode(const float* in, int H, int W, int s, float* out);

// B = clip(D(A) - E(A) + D(M) - E(M), 0, 1). A, M, B: [H, W] (BandRows below, row by row).
void boundary_band(const float* A, const float* M, int H, int W, int s, float* B);

// Eq. 14 for images with C channels. pred, gt: [H, W, C] (channel stride `cstride` >= C, channels at
// offset 0 of each pixel block), B: [H, W]. grad (may be null) receives scale * dL/dpred added into
// [H, W, cstride]. band_total: sum_d ||W^d||_1 of B when the caller has it (band_weight_total), < 0 = computed
// here. Returns L.
template <class T>
T bro_loss(const T* pred, const T* gt, int cstride, int C, const float* B, int H, int W, T eps, T* grad, T scale,
           double band_total = -1);

// Eq. 14 pixel by pixel, for scoring parts of an image (object_losses.cpp), on contiguous C-channel images.
// Each difference is charged to its first pixel p (the x pair (p, p + 1), the y pair (p, p + W)):
// wsum [H, W] receives W^x(p) + W^y(p) and num [H, W] sum_c W^x(p) |r^x_c| + W^y(p) |r^y_c| (both overwritten), so
// L = sum num / (C sum wsum + eps); unit [H, W, C] (overwritten) receives d(sum num)/dpred, so that eq. 14's
// gradient is unit / (C sum wsum + eps). pred, gt: [H, W, C]; B: [H, W].
template <class T>
void bro_parts(const T* pred, const T* gt, int C, const float* B, int H, int W, double* wsum, double* num, T* unit);

// boundary_band row by row, for passes that stream an image (object_losses.cpp): B's rows on demand, the same
// values bitwise. After reset, row(y) for y increasing (from any first row) reads A's and M's rows through the
// callbacks (each row once, in increasing order, up to y + s - 1 - s/2) and keeps the horizontal filters of the
// last s rows; the row it returns [W] stays valid until the row two after it is asked for.
class BandRows {
 public:
  using Row = std::function<const float*(int)>;
  void reset(int H, int W, int s);
  const float* row(int y, const Row& A, const Row& M);

 private:
  int H_ = 0, W_ = 0, s_ = 1, next_ = -1;  // next_: the next row to filter horizontally (-1: none yet)
  std::vector<float> ring_;                // [s, 4, W]: A's row max and min, M's row max and min
  std::vector<float> out_;                 // [2, W]: B's rows, by parity
  std::vector<float> tmp_;                 // [4, W]: the vertical filters of a row
};

// bro_parts row by row: each call takes row y's pairs (with row y + 1 and within the row) and writes row y's
// values of wsum, num [W] and unit [W C], the same bits as bro_parts; row y's unit also takes the y pairs of the
// previous call's row (y - 1), so after reset the first call's row lacks them, as an image's first row does.
template <class T>
class BroRows {
 public:
  void reset(int W, int C);
  // p0, q0: rows y of pred and gt [W C]; b0: row y of B [W]; p1, q1, b1: row y + 1's (null: y is the last row).
  void row(const T* p0, const T* q0, const float* b0, const T* p1, const T* q1, const float* b1, double* wsum,
           double* num, T* unit);

 private:
  int W_ = 0, C_ = 0;
  bool first_ = true;
  std::vector<T> wx_, wy_, ax_, ay_, gx_, gy_, carry_;  // [W C] each; carry_: the previous row's y pairs
};

// sum_d ||W^d||_1 of eq. 14 for the band B [H, W] (at most about 2 H W).
double band_weight_total(const float* B, int H, int W);

// The scale-invariant gradient above: g -= (<g, p> / <p, p>) p over n values (unchanged when p = 0).
// p, g: [n]
template <class T>
void remove_scale_component(const T* p, size_t n, T* g);

}  // namespace hgs::hybrid
