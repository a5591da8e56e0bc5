// Automatic mask generation: see amg.h. The predicted-IoU filter runs before the masks are upscaled, so only
// surviving masks pay for the full-resolution logits (the result is the same as upscaling all of them first).
#include "sam/amg.h"

#include <algorithm>
#include <numeric>

#include "core/error.h"

namespace hgs::sam {

std::vector<std::array<float, 2>> point_grid(int n) {
  std::vector<std::array<float, 2>> g;
  const double off = 1.0 / (2 * n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double t = n > 1 ? double(j) / (n - 1) : 0.0, s = n > 1 ? double(i) / (n - 1) : 0.0;
      g.push_back({float(off + t * (1 - 2 * off)), float(off + s * (1 - 2 * off))});  // numpy linspace
    }
  return g;
}

float stability_score(const float* logits, size_t n, float thr, float offset) {
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < n; ++i) {
    inter += logits[i] > thr + offset;
    uni += logits[i] > thr - offset;
  }
  return uni ? float(double(inter) / double(uni)) : 0.f;
}

std::vector<int> box_nms(const std::vector<std::array<float, 4>>& boxes, const std::vector<float>& scores, float thresh) {
  std::vector<int> order(boxes.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return scores[a] > scores[b]; });
  std::vector<int> keep;
  for (int i : order) {
    const auto& a = boxes[i];
    const float area_a = (a[2] - a[0]) * (a[3] - a[1]);
    bool ok = true;
    for (int k : keep) {
      const auto& b = boxes[k];
      const float iw = std::max(0.f, std::min(a[2], b[2]) - std::max(a[0], b[0]));
      const float ih = std::max(0.f, std::min(a[3], b[3]) - std::max(a[1], b[1]));
      const float inter = iw * ih, uni = area_a + (b[2] - b[0]) * (b[3] - b[1]) - inter;
      if (uni > 0 && inter / uni > thresh) {
        ok = false;
        break;
      }
    }
    if (ok) keep.push_back(i);
  }
  return keep;
}

std::vector<AmgMask> generate_masks(const SamModel& m, const ImageEmbedding& e, const AmgOptions& o,
                                    const std::function<void(int, int)>& progress) {
  if (o.points_per_side < 1 || o.points_per_batch < 1) fail("SAM masks: points per side and per batch must be >= 1");
  const int H = e.orig_h, W = e.orig_w, C = m.channels();
  const auto grid = point_grid(o.points_per_side);
  const int n = int(grid.size());
  std::vector<AmgMask> cand;
  std::vector<std::array<float, 4>> boxes;
  std::vector<float> scores;
  for (int b0 = 0; b0 < n; b0 += o.points_per_batch) {
    const int B = std::min(o.points_per_batch, n - b0);
    std::vector<float> sparse;
    std::vector<std::array<float, 2>> pts(B);
    for (int i = 0; i < B; ++i) {
      pts[i] = {grid[b0 + i][0] * W, grid[b0 + i][1] * H};
      Prompt p;
      p.points = {pts[i]};
      p.labels = {1};
      std::vector<float> s = m.encode_prompt(m.to_input(e, p));
      sparse.insert(sparse.end(), s.begin(), s.end());
    }
    const int T = int(sparse.size()) / (B * C);
    std::vector<Prediction> pred = m.decode(e.data.data(), sparse.data(), B, T);
    for (int i = 0; i < B; ++i) {
      const Prediction& p = pred[i];
      const size_t plane = size_t(p.size) * p.size;
      for (int t = 1; t < p.tokens; ++t) {  // the multimask outputs
        if (!(p.iou[t] > o.pred_iou_thresh)) continue;
        std::vector<float> full = m.upscale_masks(e, p.lowres.data() + t * plane, 1);
        const float stab = stability_score(full.data(), full.size(), 0.f, o.stability_score_offset);
        if (!(stab > o.stability_score_thresh)) continue;
        AmgMask a;
        a.mask.resize(full.size());
        int x0 = W, y0 = H, x1 = -1, y1 = -1;
        for (int y = 0; y < H; ++y)
          for (int x = 0; x < W; ++x) {
            const bool in = full[size_t(y) * W + x] > 0.f;
            a.mask[size_t(y) * W + x] = in;
            if (!in) continue;
            ++a.area;
            x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
          }
        if (a.area == 0) x0 = y0 = x1 = y1 = 0;
        a.bbox = {x0, y0, x1 - x0, y1 - y0};
        a.predicted_iou = p.iou[t];
        a.stability_score = stab;
        a.point = pts[i];
        boxes.push_back({float(x0), float(y0), float(x1), float(y1)});
        scores.push_back(a.predicted_iou);
        cand.push_back(std::move(a));
      }
    }
    if (progress) progress(b0 + B, n);
  }
  std::vector<AmgMask> out;
  for (int k : box_nms(boxes, scores, o.box_nms_thresh)) out.push_back(std::move(cand[k]));
  return out;
}

}  // namespace hgs::sam
