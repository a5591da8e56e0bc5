// Flattening of overlapping masks: paint in order of decreasing area so the smallest covering mask wins
// (ties: the mask listed first); see flatten.h.
#include "masks/flatten.h"

#include <algorithm>
#include <map>
#include <numeric>

#include "core/error.h"

namespace hgs::masks {

uint64_t rle_area(const Rle& r) {
  uint64_t a = 0;
  for (size_t i = 1; i < r.counts.size(); i += 2) a += r.counts[i];
  return a;
}

double mask_confidence(const SourceMask& m) {
  const bool has_iou = m.predicted_iou >= 0, has_stab = m.stability_score >= 0;
  if (!has_iou && !has_stab) return -1;
  const double a = has_iou ? std::clamp(m.predicted_iou, 0.0, 1.0) : 1.0;
  const double b = has_stab ? std::clamp(m.stability_score, 0.0, 1.0) : 1.0;
  return a * b;
}

std::vector<int> part_of(const std::vector<SourceMask>& masks, double min_fraction) {
  const size_t M = masks.size();
  std::vector<std::pair<uint64_t, int>> events;  // (position, +(i+1) start / -(i+1) end)
  std::vector<uint64_t> area(M, 0);
  for (size_t i = 0; i < M; ++i) {
    uint64_t pos = 0;
    const auto& c = masks[i].rle.counts;
    for (size_t k = 0; k < c.size(); ++k) {
      if ((k & 1) && c[k]) {
        events.push_back({pos, int(i) + 1});
        events.push_back({pos + c[k], -(int(i) + 1)});
        area[i] += c[k];
      }
      pos += c[k];
    }
  }
  std::sort(events.begin(), events.end());          // at one position ends (negative) come before starts
  std::map<std::pair<int, int>, uint64_t> overlap;  // (i, j), i < j -> shared pixels
  std::vector<int> active;
  uint64_t last = 0;
  for (auto [pos, e] : events) {
    if (pos > last && active.size() > 1)
      for (size_t a = 0; a < active.size(); ++a)
        for (size_t b = a + 1; b < active.size(); ++b)
          overlap[{std::min(active[a], active[b]), std::max(active[a], active[b])}] += pos - last;
    last = pos;
    if (e > 0) active.push_back(e - 1);
    else active.erase(std::find(active.begin(), active.end(), -e - 1));
  }
  std::vector<int> parent(M, -1);
  for (auto& [ij, n] : overlap)
    for (auto [i, j] : {ij, std::pair<int, int>{ij.second, ij.first}}) {  // is i a part of j?
      if (area[j] <= area[i] || double(n) < min_fraction * double(area[i])) continue;
      if (parent[i] < 0 || area[j] < area[parent[i]] || (area[j] == area[parent[i]] && j < parent[i])) parent[i] = j;
    }
  return parent;
}

Flattened flatten_masks(const std::vector<SourceMask>& masks, int width, int height) {
  const size_t M = masks.size();
  if (M > 65535) fail("{} masks in one view: label maps hold at most 65535", M);
  std::vector<uint64_t> area(M);
  for (size_t i = 0; i < M; ++i) area[i] = rle_area(masks[i].rle);
  std::vector<size_t> order(M);
  std::iota(order.begin(), order.end(), 0);
  // Painted first = largest; among equal areas the later-listed mask first, so the earlier one wins.
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return area[a] != area[b] ? area[a] > area[b] : a > b; });
  Flattened f;
  f.labels = LabelMap(width, height);
  for (size_t i : order) {
    const Rle& r = masks[i].rle;
    uint64_t pos = 0;
    for (size_t k = 0; k < r.counts.size(); ++k) {
      if (k & 1)
        for (uint64_t p = pos; p < pos + r.counts[k]; ++p)
          f.labels.v[(p % height) * width + p / height] = uint16_t(i + 1);
      pos += r.counts[k];
    }
  }
  f.visible.assign(M, 0);
  for (uint16_t l : f.labels.v)
    if (l) f.visible[l - 1]++;
  bool any_score = false;
  std::vector<float> score(M + 1, 1.f);
  for (size_t i = 0; i < M; ++i) {
    const double c = mask_confidence(masks[i]);
    if (c >= 0) {
      any_score = true;
      score[i + 1] = float(c);
    }
  }
  if (any_score) {
    f.confidence.resize(f.labels.v.size());
    for (size_t p = 0; p < f.labels.v.size(); ++p) f.confidence[p] = score[f.labels.v[p]];
  }
  return f;
}

}  // namespace hgs::masks
