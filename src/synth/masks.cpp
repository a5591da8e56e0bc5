// Simulated SAM2 masks: starting from the exact instance map of a view, apply in order an id swap between
// two objects (propagation failure), missed detections, boundary jitter (erosion or dilation of each
// object by a random radius, square element, via a chessboard distance transform), and merges of touching
// objects. Confidence is lower near label boundaries (ramp over 4 px) plus Gaussian noise.
// SAM-style masks (simulate_sam_masks): wholes, halves and background surfaces from the exact instance map and
// depth, each independently missed or eroded / dilated.
#include <algorithm>
#include <cmath>
#include <set>

#include "core/error.h"
#include "masks/per_view.h"
#include "synth/synth.h"

namespace hgs::synth {

NoiseLevel noise_level(const std::string& name, const std::string& world) {
  if (world == "realistic") {
    if (name != "none" && name != "low" && name != "medium" && name != "high")
      fail("--noise: unknown level '{}' (none, low, medium or high)", name);
    NoiseLevel n;
    if (name == "none") return n;
    const int l = name == "low" ? 0 : name == "medium" ? 1 : 2;
    const double pick[][3] = {                       // low, medium, high
                              {0.05, 0.10, 0.20},    // confused pairs (per touching pair, drawn once)
                              {0.002, 0.005, 0.01},  // identity swaps (touching pair, view)
                              {0.04, 0.07, 0.10},    // confidence noise
                              {0.02, 0.04, 0.06},    // small-object loss, added
                              {0.10, 0.25, 0.40},    // parts
                              {0.002, 0.005, 0.01},  // track lost
                              {0.10, 0.12, 0.15},    // track lost when suddenly occluded, added
                              {3, 3.5, 4},           // mean lost run
                              {0.3, 0.5, 0.6},       // re-born under a new id
                              {1, 2, 3},             // edge bias
                              {2, 3, 4},             // surface pieces
                              {0.15, 0.20, 0.30},    // view bias
                              {0.35, 0.55, 0.75},    // confusion
                              {0.10, 0.15, 0.20}};   // patch noise
    n.jitter = 1;
    n.merge = pick[0][l], n.swap = pick[1][l], n.conf_noise = pick[2][l], n.small_miss = pick[3][l];
    n.split = pick[4][l], n.lose = pick[5][l], n.occluded_lose = pick[6][l], n.run_mean = pick[7][l];
    n.reborn = pick[8][l], n.edge_bias = int(pick[9][l]), n.pieces = int(pick[10][l]), n.view_bias = pick[11][l];
    n.confusion = pick[12][l], n.patch_noise = pick[13][l];
    n.feature = n.patch_noise;  // the SfM points' noise follows whether there is feature noise
    return n;
  }
  // miss, jitter, merge, swap, confidence noise, feature noise, small-object miss, split
  if (name == "none") return {0, 0, 0, 0, 0, 0, 0, 0};
  if (name == "low") return {0.02, 1, 0.05, 0.02, 0.04, 0.3, 0.10, 0.10};
  if (name == "medium") return {0.04, 2, 0.05, 0.04, 0.07, 0.5, 0.20, 0.25};
  if (name == "high") return {0.10, 3, 0.15, 0.10, 0.10, 0.8, 0.35, 0.40};
  fail("--noise: unknown level '{}' (none, low, medium or high)", name);
}

NoiseLevel noise_of(const SynthOptions& opt) {
  NoiseLevel nl = noise_level(opt.noise, opt.world);
  if (opt.miss_rate >= 0) (opt.world == "realistic" ? nl.lose : nl.miss) = opt.miss_rate;
  if (opt.small_miss_rate >= 0) nl.small_miss = opt.small_miss_rate;
  if (opt.merge_rate >= 0) nl.merge = opt.merge_rate;
  if (opt.split_rate >= 0) nl.split = opt.split_rate;
  if (opt.objects_only) nl.small_miss = nl.split = 0, nl.pieces = std::min(nl.pieces, 1);
  return nl;
}

Eigen::Vector3d pixel_world_point(const RenderedView& v, const Intrinsics& K, int x, int y) {
  const double z = v.depth[size_t(y) * v.rgb.width + x];
  const Vec3 pc((x + 0.5 - K.cx) / K.fx * z, (y + 0.5 - K.cy) / K.fy * z, z);
  return v.R.transpose() * (pc - v.t);
}

using masks::chessboard_distance;  // masks/per_view.h

std::set<std::pair<int, int>> touching_pairs(const LabelMap& m, int max_label) {
  std::set<std::pair<int, int>> touching;
  for (int y = 0; y < m.height; ++y)
    for (int x = 0; x < m.width; ++x) {
      const int a = m.at(x, y);
      if (!a || a > max_label) continue;
      for (auto [dx, dy] : {std::pair{1, 0}, std::pair{0, 1}}) {
        if (x + dx >= m.width || y + dy >= m.height) continue;
        const int b = m.at(x + dx, y + dy);
        if (b && b <= max_label && b != a) touching.insert({std::min(a, b), std::max(a, b)});
      }
    }
  return touching;
}

void shift_edge(LabelMap& m, int k, int r, bool keep_half) {
  if (r == 0) return;
  const bool erode = r < 0;
  const size_t n = m.v.size();
  std::vector<uint8_t> src(n);
  for (size_t p = 0; p < n; ++p) src[p] = erode ? (m.v[p] != k) : (m.v[p] == k);
  const std::vector<int> d = chessboard_distance(src, m.width, m.height);
  if (erode && keep_half) {  // the largest radius that removes at most half of the object
    std::vector<size_t> depth_count(size_t(-r) + 2, 0);
    size_t total = 0;
    for (size_t p = 0; p < n; ++p)
      if (m.v[p] == k) ++total, ++depth_count[size_t(std::min(d[p], -r + 1))];
    size_t removed = 0;
    int radius = 0;
    for (int q = 1; q <= -r && 2 * (removed + depth_count[size_t(q)]) <= total; ++q)
      removed += depth_count[size_t(q)], radius = q;
    r = -radius;
  }
  for (size_t p = 0; p < n; ++p) {
    if (erode && m.v[p] == k && d[p] <= -r) m.v[p] = 0;
    if (!erode && m.v[p] == 0 && d[p] <= r) m.v[p] = static_cast<uint16_t>(k);
  }
}

std::vector<float> edge_confidence(const LabelMap& mask, double noise, Rng& rng) {
  if (noise <= 0) return {};
  const std::vector<int> d = chessboard_distance(masks::label_edges(mask), mask.width, mask.height);
  std::vector<float> conf(mask.v.size());
  for (size_t i = 0; i < conf.size(); ++i) {
    const double c = 0.45 + 0.55 * std::min(1.0, d[i] / 4.0) + noise * rng.normal();
    conf[i] = static_cast<float>(std::clamp(c, 0.0, 1.0));
  }
  return conf;
}

std::vector<SamMask> simulate_sam_masks(const RenderedView& v, const Intrinsics& K, const World& world,
                                        const std::vector<char>& split, const NoiseLevel& nl, uint64_t seed) {
  const int w = v.rgb.width, h = v.rgb.height, nobj = int(world.objects.size());
  const size_t n = size_t(w) * h;
  Rng rng(seed);
  std::vector<SamMask> out;
  auto add = [&](int entity, std::vector<uint8_t> inside) {
    if (rng.chance(nl.miss)) return;
    if (nl.jitter > 0) {
      const int r = rng.integer(0, nl.jitter);
      const bool erode = rng.chance(0.5);
      if (r > 0) {
        std::vector<uint8_t> src(n);
        for (size_t i = 0; i < n; ++i) src[i] = erode ? !inside[i] : inside[i];
        std::vector<int> d = chessboard_distance(src, w, h);
        for (size_t i = 0; i < n; ++i) {
          if (erode && inside[i] && d[i] <= r) inside[i] = 0;
          if (!erode && !inside[i] && d[i] <= r) inside[i] = 1;
        }
      }
    }
    size_t area = 0;
    for (uint8_t b : inside) area += b;
    if (area < 16) return;
    SamMask m;
    m.inside = std::move(inside);
    m.entity = entity;
    m.predicted_iou = std::round(rng.uniform(0.86, 1.0) * 1e4) / 1e4;
    m.stability_score = std::round(rng.uniform(0.9, 1.0) * 1e4) / 1e4;
    out.push_back(std::move(m));
  };
  for (int k = 1; k <= nobj; ++k) {
    std::vector<uint8_t> inside(n), half1(n), half2(n);
    size_t a = 0, a1 = 0, a2 = 0;
    const double split_x = world.objects[k - 1].position.x();
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const size_t p = size_t(y) * w + x;
        if (v.instances.v[p] != k) continue;
        inside[p] = 1;
        ++a;
        if (!split[k - 1]) continue;
        if (pixel_world_point(v, K, x, y).x() < split_x) half1[p] = 1, ++a1;
        else half2[p] = 1, ++a2;
      }
    if (!a) continue;
    add(k, std::move(inside));
    if (a1 >= 16 && a2 >= 16) {
      add(nobj + 2 * (k - 1) + 1, std::move(half1));
      add(nobj + 2 * (k - 1) + 2, std::move(half2));
    }
  }
  int max_concept = 0;
  for (uint16_t c : v.concept_id) max_concept = std::max<int>(max_concept, c);
  for (int c = 1; c <= max_concept; ++c) {
    std::vector<uint8_t> inside(n);
    size_t a = 0;
    for (size_t p = 0; p < n; ++p)
      if (v.instances.v[p] == 0 && v.concept_id[p] == c) inside[p] = 1, ++a;
    if (a) add(3 * nobj + c, std::move(inside));
  }
  for (size_t i = out.size(); i > 1; --i) std::swap(out[i - 1], out[size_t(rng.integer(0, int(i) - 1))]);
  return out;
}

void simulate_masks(const LabelMap& gt, const NoiseLevel& nl, int num_objects, uint64_t seed, LabelMap& mask,
                    std::vector<float>& conf) {
  const size_t n = gt.v.size();
  mask = gt;
  Rng rng(seed);
  std::vector<int> present;
  std::vector<int> count(num_objects + 1, 0);  // [K + 1] pixels of each object in the view
  for (uint16_t l : gt.v)
    if (l && l <= num_objects) count[l]++;
  for (int k = 1; k <= num_objects; ++k)
    if (count[k] > 0) present.push_back(k);
  // 1. id swap (a propagation failure exchanges two identities in this view)
  if (present.size() >= 2 && rng.chance(nl.swap)) {
    int a = present[rng.integer(0, int(present.size()) - 1)], b;
    do {
      b = present[rng.integer(0, int(present.size()) - 1)];
    } while (b == a);
    for (auto& l : mask.v) l = l == a ? b : l == b ? a : l;
  }
  // 2-3. missed detections (more often for small objects) and boundary jitter
  const double small = kSmallObjectFraction * double(n);
  for (int k : present) {
    if (rng.chance(nl.miss + (count[k] < small ? nl.small_miss : 0.0))) {
      for (auto& l : mask.v)
        if (l == k) l = 0;
      continue;
    }
    if (nl.jitter <= 0) continue;
    int r = rng.integer(0, nl.jitter);
    bool erode = rng.chance(0.5);
    if (r == 0) continue;
    shift_edge(mask, k, erode ? -r : r, false);
  }
  // 4. merges of touching objects (4-neighbours with two different object labels)
  if (nl.merge > 0) {
    const std::set<std::pair<int, int>> touching = touching_pairs(mask, 0xFFFF);
    for (auto [a, b] : touching) {
      if (!rng.chance(nl.merge)) continue;
      for (auto& l : mask.v)
        if (l == b) l = static_cast<uint16_t>(a);
    }
  }
  // 5. confidence
  conf = edge_confidence(mask, nl.conf_noise, rng);
}

}  // namespace hgs::synth
