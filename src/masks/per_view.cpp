// Core pixels (separable min / max of labels), the folding of parts into their whole and their clipping to it,
// robust spread (per_view.h).
#include "masks/per_view.h"

#include <algorithm>

#include "core/error.h"
#include "masks/rle.h"

namespace hgs::masks {

std::vector<uint8_t> core_pixels(const LabelMap& m, int r) {
  const int W = m.width, H = m.height;
  std::vector<uint8_t> core(size_t(W) * H, 1);
  if (r <= 0) return core;
  std::vector<uint16_t> hmin(core.size()), hmax(core.size());
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      uint16_t lo = 65535, hi = 0;
      for (int dx = std::max(0, x - r); dx <= std::min(W - 1, x + r); ++dx)
        lo = std::min(lo, m.at(dx, y)), hi = std::max(hi, m.at(dx, y));
      hmin[size_t(y) * W + x] = lo, hmax[size_t(y) * W + x] = hi;
    }
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      uint16_t lo = 65535, hi = 0;
      for (int dy = std::max(0, y - r); dy <= std::min(H - 1, y + r); ++dy)
        lo = std::min(lo, hmin[size_t(dy) * W + x]), hi = std::max(hi, hmax[size_t(dy) * W + x]);
      core[size_t(y) * W + x] = lo == hi;
    }
  return core;
}

std::map<int, int> part_roots(const std::map<int, MaskInfo>& info, double image_px, double max_area) {
  std::map<int, double> child_area;
  for (auto& [id, m] : info)
    if (m.part_of > 0) child_area[m.part_of] += m.area;
  std::map<int, int> root;
  for (auto& [id, m] : info) {
    int r = id;
    for (int step = 0; step < 64; ++step) {
      auto it = info.find(info.at(r).part_of);
      if (info.at(r).part_of <= 0 || it == info.end()) break;
      const MaskInfo& p = it->second;
      const bool tiled = p.visible < 0.5 * p.area || child_area[it->first] >= 0.5 * p.area;
      if (!tiled || p.area > max_area * image_px) break;
      r = it->first;
    }
    root[id] = r;
  }
  return root;
}

bool clip_parts_to_wholes(const std::vector<SourceMask>& masks, const std::map<int, int>& root, int width, int height,
                          Flattened& out) {
  const int M = int(masks.size());
  std::map<int, std::vector<uint8_t>> whole;  // root index -> its own pixels [H, W]
  std::vector<SourceMask> clipped;
  for (auto& [id, r] : root) {
    if (id == r || id < 1 || id > M || r < 1 || r > M) continue;
    if (clipped.empty()) clipped = masks;
    auto it = whole.find(r - 1);
    if (it == whole.end()) it = whole.emplace(r - 1, rle_decode(masks[r - 1].rle, masks[r - 1].source)).first;
    std::vector<uint8_t> px = rle_decode(masks[id - 1].rle, masks[id - 1].source);
    for (size_t p = 0; p < px.size(); ++p) px[p] &= it->second[p];
    clipped[id - 1].rle = rle_encode(px, width, height);
  }
  if (clipped.empty()) return false;
  out = flatten_masks(clipped, width, height);
  return true;
}

std::vector<uint8_t> label_edges(const LabelMap& m) {
  const int W = m.width, H = m.height;
  std::vector<uint8_t> edge(size_t(W) * H, 0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const uint16_t l = m.at(x, y);
      edge[size_t(y) * W + x] = (x > 0 && m.at(x - 1, y) != l) || (x + 1 < W && m.at(x + 1, y) != l) ||
                                (y > 0 && m.at(x, y - 1) != l) || (y + 1 < H && m.at(x, y + 1) != l);
    }
  return edge;
}

std::vector<int> chessboard_distance(const std::vector<uint8_t>& src, int w, int h) {
  const int inf = w + h;
  std::vector<int> d(src.size());
  for (size_t i = 0; i < src.size(); ++i) d[i] = src[i] ? 0 : inf;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      int& v = d[size_t(y) * w + x];
      if (x > 0) v = std::min(v, d[size_t(y) * w + x - 1] + 1);
      if (y > 0)
        for (int dx = -1; dx <= 1; ++dx)
          if (x + dx >= 0 && x + dx < w) v = std::min(v, d[size_t(y - 1) * w + x + dx] + 1);
    }
  for (int y = h - 1; y >= 0; --y)
    for (int x = w - 1; x >= 0; --x) {
      int& v = d[size_t(y) * w + x];
      if (x + 1 < w) v = std::min(v, d[size_t(y) * w + x + 1] + 1);
      if (y + 1 < h)
        for (int dx = -1; dx <= 1; ++dx)
          if (x + dx >= 0 && x + dx < w) v = std::min(v, d[size_t(y + 1) * w + x + dx] + 1);
    }
  return d;
}

void edge_ramp_confidence(const LabelMap& labels, int ramp, std::vector<float>& conf) {
  const size_t n = size_t(labels.width) * labels.height;
  if (conf.empty()) conf.assign(n, 1.f);
  if (conf.size() != n)
    fail("edge_ramp_confidence: {} confidences for a {}x{} label map", conf.size(), labels.width, labels.height);
  if (ramp <= 0) return;
  const std::vector<int> d = chessboard_distance(label_edges(labels), labels.width, labels.height);
  for (size_t p = 0; p < n; ++p) conf[p] *= 0.5f + 0.5f * std::min(1.f, float(d[p]) / float(ramp));
}

double robust_spread(const std::vector<Eigen::Vector3d>& points) {
  if (points.empty()) return 0;
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  Eigen::Vector3d c;
  for (int d = 0; d < 3; ++d) {
    std::vector<double> v;
    for (auto& p : points) v.push_back(p[d]);
    c[d] = median(v);
  }
  std::vector<double> dist;
  for (auto& p : points) dist.push_back((p - c).norm());
  const size_t q = std::min(dist.size() - 1, size_t(0.8 * double(dist.size())));
  std::nth_element(dist.begin(), dist.begin() + q, dist.end());
  return dist[q];
}

}  // namespace hgs::masks
