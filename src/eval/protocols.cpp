// LERF-OVS post-processing / localisation and 3D-OVS per-image scoring; see protocols.h for the formulas.
#include "eval/protocols.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "eval/filters.h"

namespace hgs::eval {

LerfPost lerf_postprocess(const std::vector<float>& v, int width, int height, const LerfOptions& opt) {
  if (width <= 0 || height <= 0 || v.size() != size_t(width) * height)
    fail("eval: relevancy map holds {} values, expected {}x{}", v.size(), width, height);
  LerfPost P;
  P.smoothed.resize(v.size());
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i]))
      fail("eval: relevancy map holds a non-finite value at pixel ({}, {})", i % width, i / width);
  P.boxed = box_filter(v, width, height, opt.box);
  for (size_t i = 0; i < v.size(); ++i) {
    P.smoothed[i] = 0.5f * (P.boxed[i] + v[i]);
    lo = std::min(lo, P.smoothed[i]);
    hi = std::max(hi, P.smoothed[i]);
  }
  P.activation.resize(v.size());
  P.raw_mask.resize(v.size());
  const double scale = 1.0 / (double(hi) - double(lo) + 1e-9);
  for (size_t i = 0; i < v.size(); ++i) {
    const double n = (double(P.smoothed[i]) - lo) * scale;
    P.activation[i] = static_cast<float>(std::clamp(2.0 * n - 1.0, 0.0, 1.0));
    P.raw_mask[i] = P.activation[i] > opt.threshold ? 1 : 0;
  }
  P.mask = opt.majority > 1 ? majority_filter(P.raw_mask, width, height, opt.majority) : P.raw_mask;
  return P;
}

Localisation lerf_localise(const std::vector<float>& boxed, int width, int height, const std::vector<BBox>& bboxes) {
  if (width <= 0 || height <= 0 || boxed.size() != size_t(width) * height)
    fail("eval: filtered relevancy map holds {} values, expected {}x{}", boxed.size(), width, height);
  Localisation L;
  const float mx = *std::max_element(boxed.begin(), boxed.end());
  L.score = mx;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      if (boxed[size_t(y) * width + x] != mx) continue;
      if (L.x < 0) {
        L.x = x;
        L.y = y;
      }
      for (auto& b : bboxes)
        if (b.contains_pixel(x, y)) {  // report the tied maximum that hits
          L.x = x;
          L.y = y;
          L.hit = true;
          return L;
        }
    }
  return L;
}

LerfQueryResult evaluate_lerf_query(const std::vector<float>& relevancy, int width, int height, const LerfCategory& gt,
                                    const LerfOptions& opt) {
  if (gt.mask.size() != size_t(width) * height)
    fail("eval: ground truth of \"{}\" holds {} pixels, expected {}x{}", gt.name, gt.mask.size(), width, height);
  LerfQueryResult R;
  R.post = lerf_postprocess(relevancy, width, height, opt);
  R.scores = score_mask(gt.mask, R.post.mask, width, height, opt.boundary_d);
  R.loc = lerf_localise(R.post.boxed, width, height, gt.bboxes);
  return R;
}

LerfOptions scaled_lerf_options(int width, const LerfOptions& base) {
  if (width <= 0) fail("eval: cannot scale LERF's windows to an image {} pixels wide", width);
  LerfOptions o = base;
  const double f = double(width) / double(kLerfReferenceWidth);
  o.box = std::max(1, static_cast<int>(std::lround(base.box * f)));
  const int m = static_cast<int>(std::floor(base.majority * f));
  o.majority = m >= 3 ? (m % 2 ? m : m - 1) : 1;
  return o;
}

std::vector<uint16_t> argmax_classes(const std::vector<std::vector<float>>& rel, int width, int height) {
  if (rel.empty()) fail("eval: 3D-OVS argmax needs at least one class relevancy map");
  if (rel.size() > 65535) fail("eval: too many classes ({})", rel.size());
  const size_t n = size_t(width) * height;
  for (size_t c = 0; c < rel.size(); ++c)
    if (rel[c].size() != n)
      fail("eval: relevancy map of class {} holds {} values, expected {}x{}", c, rel[c].size(), width, height);
  std::vector<uint16_t> pred(n, 0);
  for (size_t i = 0; i < n; ++i) {
    float best = rel[0][i];
    for (size_t c = 1; c < rel.size(); ++c)
      if (rel[c][i] > best) {
        best = rel[c][i];
        pred[i] = static_cast<uint16_t>(c);
      }
  }
  return pred;
}

namespace {

// The pixels some class mask covers, gt [C][H, W] -> [H, W].
Mask labelled_pixels(const std::vector<Mask>& gt) {
  Mask l(gt[0].size(), 0);
  for (const Mask& m : gt)
    for (size_t i = 0; i < l.size(); ++i) l[i] |= m[i] != 0;
  return l;
}

}  // namespace

double ovs_ceiling(const std::vector<Mask>& gt, OvsScoring scoring) {
  if (gt.empty()) fail("eval: 3D-OVS evaluation needs at least one class mask");
  if (scoring == OvsScoring::LabelledOnly) return 1.0;
  const size_t n = gt[0].size(), C = gt.size();
  size_t present = 0, largest = 0;
  for (const Mask& m : gt) {
    const size_t g = size_t(std::count_if(m.begin(), m.end(), [](uint8_t v) { return v != 0; }));
    present += g > 0;
    largest = std::max(largest, g);
  }
  const Mask lab = labelled_pixels(gt);
  const double V = double(n - size_t(std::count(lab.begin(), lab.end(), uint8_t(1))));
  if (present < C || V == 0) return double(present) / double(C);
  return (double(C) - V / (double(largest) + V)) / double(C);
}

OvsImageResult evaluate_3dovs_prediction(const std::vector<uint16_t>& prediction, const std::vector<Mask>& gt,
                                         int width, int height, int boundary_d, OvsScoring scoring) {
  const size_t n = size_t(width) * height;
  if (width <= 0 || height <= 0 || prediction.size() != n)
    fail("eval: class prediction holds {} values, expected {}x{}", prediction.size(), width, height);
  if (gt.empty()) fail("eval: 3D-OVS evaluation needs at least one class mask");
  const size_t C = gt.size();
  for (size_t c = 0; c < C; ++c)
    if (gt[c].size() != n)
      fail("eval: ground-truth mask of class {} holds {} pixels, expected {}x{}", c, gt[c].size(), width, height);
  if (boundary_d <= 0) boundary_d = boundary_width(width, height);
  const bool labelled_only = scoring == OvsScoring::LabelledOnly;
  const Mask scored = labelled_only ? labelled_pixels(gt) : Mask(n, 1);  // the pixels scored
  OvsImageResult R;
  R.prediction = prediction;
  R.iou.resize(C);
  R.biou.resize(C);
  R.ceiling = ovs_ceiling(gt, scoring);
  Mask pm(n);
  size_t counted = 0;
  for (size_t c = 0; c < C; ++c) {
    for (size_t i = 0; i < n; ++i) pm[i] = prediction[i] == c && scored[i] ? 1 : 0;
    const Confusion cf = confusion(gt[c], pm, width, height);
    const bool in_frame = cf.tp + cf.fn > 0;
    if (labelled_only && !in_frame) {
      R.iou[c] = R.biou[c] = std::numeric_limits<double>::quiet_NaN();
      continue;
    }
    const bool absent = cf.tp + cf.fp + cf.fn == 0;
    R.iou[c] = absent ? 0.0 : double(cf.tp) / double(cf.tp + cf.fp + cf.fn);
    R.biou[c] = absent ? 0.0 : boundary_iou(gt[c], pm, width, height, boundary_d);
    R.miou += R.iou[c];
    R.mbiou += R.biou[c];
    ++counted;
  }
  long correct = 0, total = 0;
  for (size_t i = 0; i < n; ++i) {
    if (!scored[i]) continue;
    const size_t p = prediction[i];
    bool ok = p < C;
    for (size_t c = 0; c < C && ok; ++c) ok = (gt[c][i] != 0) == (c == p);
    correct += ok;
    ++total;
  }
  R.miou = counted ? R.miou / double(counted) : std::numeric_limits<double>::quiet_NaN();
  R.mbiou = counted ? R.mbiou / double(counted) : std::numeric_limits<double>::quiet_NaN();
  R.accuracy = total ? double(correct) / double(total) : std::numeric_limits<double>::quiet_NaN();
  return R;
}

OvsImageResult evaluate_3dovs_image(const std::vector<std::vector<float>>& relevancy, const std::vector<Mask>& gt,
                                    int width, int height, int boundary_d, OvsScoring scoring) {
  if (relevancy.size() != gt.size())
    fail("eval: {} class relevancy maps for {} ground-truth classes", relevancy.size(), gt.size());
  return evaluate_3dovs_prediction(argmax_classes(relevancy, width, height), gt, width, height, boundary_d, scoring);
}

}  // namespace hgs::eval
