// Greedy one-to-one matching of mask ids to true objects on summed per-view IoU, then mean per-view IoU
// (association_score.h).
#include "eval/association_score.h"

#include <algorithm>
#include <tuple>

#include "core/error.h"
#include "core/image.h"
#include "eval/metrics.h"
#include "scene/scene.h"

namespace hgs::eval {
namespace fs = std::filesystem;

AssociationScore score_association(const fs::path& scene, const fs::path& masks_dir, int min_pixels, bool test_only) {
  Scene s = load_scene(scene);
  struct ViewCounts {
    fs::path gt, pred;  // the label maps, read again for the boundaries
    std::map<int, long> gt_area, pred_area;
    std::map<std::pair<int, int>, long> inter;  // (pred, gt)
  };
  std::vector<ViewCounts> vc;
  std::map<std::pair<int, int>, double> total;  // (pred, gt) -> sum of per-view IoU
  for (auto& v : s.views) {
    const fs::path gp = s.root / "gt" / "instances" / v.name, mp = masks_dir / (v.stem + ".png");
    if (!fs::exists(gp) || !fs::exists(mp) || (test_only && !v.is_test)) continue;
    LabelMap gt = load_label_png(gp), pr = load_label_png(mp);
    if (gt.width != pr.width || gt.height != pr.height)
      fail("{}: mask is {}x{} but {} is {}x{}", mp.string(), pr.width, pr.height, gp.string(), gt.width, gt.height);
    ViewCounts c;
    c.gt = gp;
    c.pred = mp;
    for (size_t i = 0; i < gt.v.size(); ++i) {
      if (gt.v[i]) ++c.gt_area[gt.v[i]];
      if (pr.v[i]) ++c.pred_area[pr.v[i]];
      if (gt.v[i] && pr.v[i]) ++c.inter[{pr.v[i], gt.v[i]}];
    }
    for (auto& [pg, n] : c.inter) total[pg] += double(n) / double(c.pred_area[pg.first] + c.gt_area[pg.second] - n);
    vc.push_back(std::move(c));
  }
  if (vc.empty()) fail("{}: no view has both a mask in {} and gt/instances/<name>", scene.string(), masks_dir.string());
  std::vector<std::tuple<double, int, int>> cand;
  for (auto& [pg, t] : total) cand.emplace_back(-t, pg.first, pg.second);
  std::sort(cand.begin(), cand.end());
  AssociationScore r;
  std::map<int, int> used_pred;
  for (auto& [t, p, g] : cand) {
    if (r.match.count(g) || used_pred.count(p)) continue;
    r.match[g] = p;
    used_pred[p] = g;
  }
  r.views = int(vc.size());
  std::map<int, std::pair<double, int>> per_obj;
  double sum = 0, bsum = 0, found_bsum = 0;
  int above = 0;
  for (auto& c : vc) {
    const LabelMap gt = load_label_png(c.gt), pr = load_label_png(c.pred);
    Mask gm(gt.v.size()), pm(gt.v.size());
    for (auto& [g, ga] : c.gt_area) {
      if (ga < min_pixels) continue;
      double iou = 0;
      const auto it = r.match.find(g);
      if (it != r.match.end()) {
        auto in = c.inter.find({it->second, g});
        const long n = in == c.inter.end() ? 0 : in->second;
        const long pa = c.pred_area.count(it->second) ? c.pred_area.at(it->second) : 0;
        iou = double(n) / double(pa + ga - n);
      }
      const int p = it == r.match.end() ? -1 : it->second;
      for (size_t i = 0; i < gt.v.size(); ++i) gm[i] = gt.v[i] == g, pm[i] = int(pr.v[i]) == p;
      const double b = boundary_iou(gm, pm, gt.width, gt.height);  // gm has a boundary: never NaN
      sum += iou;
      bsum += b;
      above += iou >= 0.5;
      if (iou >= 0.5) found_bsum += b;
      ++r.pairs;
      per_obj[g].first += iou;
      per_obj[g].second += 1;
    }
  }
  r.mean_biou = r.pairs ? bsum / r.pairs : 0;
  r.found_mean_biou = above ? found_bsum / above : 0;
  r.mean_iou = r.pairs ? sum / r.pairs : 0;
  r.pairs_above_half = r.pairs ? double(above) / r.pairs : 0;
  for (auto& [g, si] : per_obj) r.object_iou[g] = si.first / si.second, r.object_mean_iou += si.first / si.second;
  if (!per_obj.empty()) r.object_mean_iou /= double(per_obj.size());
  return r;
}

}  // namespace hgs::eval
