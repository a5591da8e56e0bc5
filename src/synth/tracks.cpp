// SAM2-like masks over the capture order (tracks.h). Per view, in object-index space (k = object k): the truth,
// minus the objects whose track is lost, each object eroded or dilated by its edge bias (a chessboard distance
// transform, square element), touching pairs under one mask while merged; then the background surfaces' pieces
// (nearest seed point in the world) and the parts; finally every object index mapped to the id its track shows
// (after swaps and re-births). Confidence as in the simple world: 0.45 at label boundaries rising to 1 at 4 px,
// plus noise.
#include "synth/tracks.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <set>

namespace hgs::synth {

Sam2Simulator::Sam2Simulator(const World& world, const Intrinsics& cam, const std::vector<RenderedView>& views,
                             const std::vector<int>& surfaces, const std::vector<std::string>& concept_names,
                             const std::vector<int>& part_id, const NoiseLevel& nl, int first_free_id, uint64_t seed)
    : world_(world),
      cam_(cam),
      views_(views),
      surfaces_(surfaces),
      part_id_(part_id),
      nl_(nl),
      rng_(seed),
      K_(int(world.objects.size())),
      next_id_(first_free_id) {
  id_.resize(K_);
  for (int k = 0; k < K_; ++k) id_[k] = k + 1, names_[k + 1] = world.objects[k].name;
  lost_left_.assign(K_, 0);
  reborn_.assign(K_, 0);
  last_area_.assign(K_, 0);
  tracks_.assign(K_, 1);
  bias_.resize(K_);
  // The level's bias is in pixels of a 320x240 view; SAM's edge errors scale with the image.
  const int bias =
      nl_.edge_bias > 0 ? std::max(1, int(std::lround(nl_.edge_bias * std::min(cam.width, cam.height) / 240.0))) : 0;
  for (int k = 0; k < K_; ++k) bias_[k] = bias > 0 ? rng_.integer(-bias, bias) : 0;
  surface_of_concept_.assign(concept_names.size(), 0);
  for (size_t j = 0; j < surfaces_.size(); ++j) {
    surface_of_concept_[surfaces_[j]] = int(j) + 1;
    surface_names_.push_back(concept_names[surfaces_[j]]);
  }
  // Piece seeds: world points of the surface seen in the views (every 7th pixel that shows it), `pieces` of them
  // drawn at random, so the pieces cover what the cameras see of it.
  const int pieces = std::max(1, nl_.pieces);
  seeds_.resize(surfaces_.size());
  piece_first_.resize(surfaces_.size());
  std::vector<std::vector<Vec3>> seen(surfaces_.size());
  for (const RenderedView& v : views_)
    for (size_t p = 0; p < v.concept_id.size(); p += 7) {
      const int j = surface_of_concept_[v.concept_id[p]] - 1;
      if (j < 0 || v.instances.v[p] != 0 || v.depth[p] <= 0) continue;
      seen[j].push_back(pixel_world_point(v, cam_, int(p % v.rgb.width), int(p / v.rgb.width)));
    }
  for (size_t j = 0; j < surfaces_.size(); ++j) {
    piece_first_[j] = K_ + 1 + int(j) * pieces;
    for (int q = 0; q < pieces; ++q) {
      if (!seen[j].empty()) seeds_[j].push_back(seen[j][size_t(rng_.integer(0, int(seen[j].size()) - 1))]);
      const std::string& name = surface_names_[j];
      names_[piece_first_[j] + q] = pieces == 1 ? name : fmt::format("{} (piece {})", name, q + 1);
    }
  }
  for (int k = 0; k < K_; ++k)
    if (part_id_[k]) names_[part_id_[k]] = fmt::format("{} (part)", world.objects[k].name);
}

void Sam2Simulator::rebirth(int k) {
  id_[k - 1] = next_id_++;
  names_[id_[k - 1]] = fmt::format("{} (track {})", world_.objects[k - 1].name, ++tracks_[k - 1]);
}

void Sam2Simulator::next(int i, LabelMap& mask, std::vector<float>& conf, std::map<int, IdTruth>& truth) {
  const RenderedView& rv = views_[i];
  const LabelMap& gt = rv.instances;
  const int w = gt.width, h = gt.height;
  const size_t n = gt.v.size();
  std::vector<size_t> area(K_ + 1, 0);
  for (uint16_t l : gt.v)
    if (l && l <= K_) area[l]++;
  // Touching pairs in the truth (4-neighbours with two different objects).
  const std::set<std::pair<int, int>> touching = touching_pairs(gt, K_);
  // 1. Tracks: lost runs (in capture order, visible or not), re-births, losses.
  std::vector<char> shown(K_ + 1, 0);
  const double small = kSmallObjectFraction * double(n);
  for (int k = 1; k <= K_; ++k) {
    if (lost_left_[k - 1] > 0) {
      if (--lost_left_[k - 1] == 0 && reborn_[k - 1]) rebirth(k);
      continue;
    }
    if (!area[k]) continue;
    double p = nl_.lose + (double(area[k]) < small ? nl_.small_miss : 0.0);
    if (last_area_[k - 1] && double(area[k]) < 0.4 * double(last_area_[k - 1])) p += nl_.occluded_lose;
    if (rng_.chance(p)) {
      // run length: geometric with mean run_mean (this view is its first)
      int len = 1;
      const double stop = 1.0 / std::max(1.0, nl_.run_mean);
      while (len < 1000 && !rng_.chance(stop)) ++len;
      lost_left_[k - 1] = len - 1;
      reborn_[k - 1] = rng_.chance(nl_.reborn);
      if (len == 1 && reborn_[k - 1]) rebirth(k);
      continue;
    }
    shown[k] = 1;
    last_area_[k - 1] = area[k];
  }
  // 2. Swaps of touching pairs (persist); a pair SAM confuses (drawn once, when it first touches) is under one mask
  // in every view where the two touch (SAM's group granularity), apart where they do not.
  for (auto& [pair, on] : merged_) on = false;
  for (const auto& pair : touching) {
    if (rng_.chance(nl_.swap)) std::swap(id_[pair.first - 1], id_[pair.second - 1]);
    if (!confusable_.count(pair)) confusable_[pair] = rng_.chance(nl_.merge);
    merged_[pair] = confusable_[pair];
  }
  // 3. Object masks with edge bias (object-index space).
  LabelMap m(w, h);
  for (size_t p = 0; p < n; ++p)
    if (gt.v[p] && gt.v[p] <= K_ && shown[gt.v[p]]) m.v[p] = gt.v[p];
  for (int k = 1; k <= K_; ++k) {
    if (!shown[k]) continue;
    int r = bias_[k - 1];
    if (nl_.jitter > 0 && rng_.chance(0.3)) r += rng_.chance(0.5) ? 1 : -1;
    shift_edge(m, k, r, true);  // SAM's bias thins an object's edge, never the whole object
  }
  for (const auto& [pair, on] : merged_)
    if (on && shown[pair.first] && shown[pair.second])
      for (auto& l : m.v)
        if (l == pair.second) l = uint16_t(pair.first);
  // 4. Displayed ids: objects through their tracks, surface pieces, parts.
  mask = LabelMap(w, h);
  truth.clear();
  for (size_t p = 0; p < n; ++p) {
    const int k = m.v[p];
    const int x = int(p % w), y = int(p / w);
    if (k) {
      int id = id_[k - 1];
      if (part_id_[k - 1] && gt.v[p] == k &&
          pixel_world_point(rv, cam_, x, y).z() >= world_.objects[k - 1].position.z()) {
        id = part_id_[k - 1];
        truth[id] = {k, "part", "", 0};
      } else if (!truth.count(id)) {
        truth[id] = {k, id > K_ ? "track" : "object", "", 0};
      }
      mask.v[p] = uint16_t(id);
      continue;
    }
    const int j = surface_of_concept_[rv.concept_id[p]] - 1;
    if (j < 0 || gt.v[p] != 0 || seeds_[j].empty()) continue;
    const Vec3 X = pixel_world_point(rv, cam_, x, y);
    int best = 0;
    double bd = 1e300;
    for (size_t q = 0; q < seeds_[j].size(); ++q) {
      const double d2 = (seeds_[j][q] - X).squaredNorm();
      if (d2 < bd) bd = d2, best = int(q);
    }
    const int id = piece_id(j, best);
    mask.v[p] = uint16_t(id);
    if (!truth.count(id)) truth[id] = {0, "surface", surface_names_[j], best + 1};
  }
  // 5. Confidence.
  conf = edge_confidence(mask, nl_.conf_noise, rng_);
}

}  // namespace hgs::synth
