// Automatic mask generation: see amg.h. The predicted-IoU filter runs before the masks are upscaled, so only
// surviving masks pay for the full-resolution logits (the result is the same as upscaling all of them first).
#include "sam/amg.h"

#include <algorithm>
#include <functional>
#include <numeric>
#include <optional>
#include <utility>

#include "core/error.h"
#include "nn/thread_pool.h"

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

std::vector<int> box_nms(const std::vector<std::array<float, 4>>& boxes, const std::vector<float>& scores,
                         float thresh) {
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

bool remove_small_regions(std::vector<uint8_t>& mask, int W, int H, int area, bool holes) {
  // 8-connected components of the pixels equal to `target` (flood fill with an explicit stack).
  const uint8_t target = holes ? 0 : 1;
  std::vector<int> label(mask.size(), -1), sizes, stack;
  for (size_t s0 = 0; s0 < mask.size(); ++s0) {
    if (mask[s0] != target || label[s0] >= 0) continue;
    const int id = int(sizes.size());
    int n = 0;
    label[s0] = id;
    stack.assign(1, int(s0));
    while (!stack.empty()) {
      const int p = stack.back();
      stack.pop_back();
      ++n;
      const int x = p % W, y = p / W;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= W || yy >= H) continue;
          const int q = yy * W + xx;
          if (mask[q] == target && label[q] < 0) {
            label[q] = id;
            stack.push_back(q);
          }
        }
    }
    sizes.push_back(n);
  }
  std::vector<uint8_t> small(sizes.size());
  bool any = false;
  for (size_t i = 0; i < sizes.size(); ++i) any |= (small[i] = sizes[i] < area);
  if (!any) return false;
  if (holes) {
    for (size_t i = 0; i < mask.size(); ++i)
      if (label[i] >= 0 && small[label[i]]) mask[i] = 1;
  } else {
    bool all_small = true;
    for (uint8_t v : small) all_small &= v != 0;
    const int largest = int(std::max_element(sizes.begin(), sizes.end()) - sizes.begin());
    for (size_t i = 0; i < mask.size(); ++i)
      if (label[i] >= 0) mask[i] = all_small ? label[i] == largest : !small[label[i]];
  }
  return true;
}

namespace {

void set_box_area(AmgMask& a, int W, int H) {
  int x0 = W, y0 = H, x1 = -1, y1 = -1;
  a.area = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (!a.mask[size_t(y) * W + x]) continue;
      ++a.area;
      x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
    }
  if (a.area == 0) x0 = y0 = x1 = y1 = 0;
  a.bbox = {x0, y0, x1 - x0, y1 - y0};
}

// fn(u) for u in [0, n) on the pool's threads, thread p taking u = p, p + T, p + 2T, ... (T threads): the
// costly items (masks that pass the thresholds) tend to be neighbours, so contiguous chunks would balance badly.
// An exception of fn reaches the caller (nn::parallel_for).
void each_of(int n, const std::function<void(int)>& fn) {
  const int T = std::min(nn::pool_threads(), std::max(n, 1));
  nn::parallel_for(T, 2, [&](long p0, long p1) {
    for (long p = p0; p < p1; ++p)
      for (long u = p; u < n; u += T) fn(int(u));
  });
}

std::array<float, 4> xyxy(const AmgMask& a) {
  return {float(a.bbox[0]), float(a.bbox[1]), float(a.bbox[0] + a.bbox[2]), float(a.bbox[1] + a.bbox[3])};
}

}  // namespace

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
    // The multimask outputs (prompt i, token t >= 1): each that passes the predicted IoU costs two full-size
    // resamplings, so they are spread over the threads (each thread every T-th output, as the passing ones
    // cluster) and collected in order.
    const int tokens = pred.empty() ? 0 : pred[0].tokens, outs = B * std::max(tokens - 1, 0);
    std::vector<std::optional<AmgMask>> kept(outs);
    each_of(outs, [&](int u) {
      const int i = u / (tokens - 1), t = 1 + u % (tokens - 1);
      const Prediction& p = pred[i];
      if (!(p.iou[t] > o.pred_iou_thresh)) return;
      const size_t plane = size_t(p.size) * p.size;
      std::vector<float> full = m.upscale_masks(e, p.lowres.data() + t * plane, 1);
      const float stab = stability_score(full.data(), full.size(), 0.f, o.stability_score_offset);
      if (!(stab > o.stability_score_thresh)) return;
      AmgMask a;
      a.mask.resize(full.size());
      for (size_t k = 0; k < full.size(); ++k) a.mask[k] = full[k] > 0.f;
      set_box_area(a, W, H);
      a.predicted_iou = p.iou[t];
      a.stability_score = stab;
      a.point = pts[i];
      kept[u] = std::move(a);
    });
    for (auto& a : kept) {
      if (!a) continue;
      boxes.push_back(xyxy(*a));
      scores.push_back(a->predicted_iou);
      cand.push_back(std::move(*a));
    }
    if (progress) progress(b0 + B, n);
  }
  std::vector<AmgMask> out;
  for (int k : box_nms(boxes, scores, o.box_nms_thresh)) out.push_back(std::move(cand[k]));
  if (o.min_mask_region_area <= 0 || out.empty()) return out;
  // Small holes and islands, then NMS again preferring the masks that did not change.
  std::vector<AmgMask> fixed = std::move(out);  // out is not read again
  std::vector<std::array<float, 4>> b2;
  std::vector<float> unchanged(fixed.size());
  each_of(int(fixed.size()), [&](int k) {
    AmgMask& a = fixed[k];
    const bool c1 = remove_small_regions(a.mask, W, H, o.min_mask_region_area, true);
    const bool c2 = remove_small_regions(a.mask, W, H, o.min_mask_region_area, false);
    set_box_area(a, W, H);
    unchanged[k] = c1 || c2 ? 0.f : 1.f;
  });
  for (const AmgMask& a : fixed) b2.push_back(xyxy(a));
  std::vector<AmgMask> res;
  for (int k : box_nms(b2, unchanged, o.box_nms_thresh)) res.push_back(std::move(fixed[k]));
  return res;
}

}  // namespace hgs::sam
