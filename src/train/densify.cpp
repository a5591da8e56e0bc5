// Densification (see densify.h): selection from the averaged NDC gradient, one row gather for clone + split
// (model and Adam moments together), then a second gather for pruning.
#include "train/densify.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace hgs::train {

void DensifyStats::reset(int n) {
  grad_accum.assign(n, 0.f);
  count.assign(n, 0);
  max_radius.assign(n, 0.f);
}

void DensifyStats::add(const float* g, const int* radii, int n, int W, int H) {
  if (int(count.size()) != n) fail("densify: statistics hold {} Gaussians, the model {}", count.size(), n);
  StepStats one;  // one view is a step of one view (same sums)
  one.add_view(g, radii, n, W, H, true);
  add(one);
}

void StepStats::add_view(const float* g, const int* radii, int count_n, int W, int H, bool first) {
  if (first) {
    n = count_n;
    v.assign(3 * size_t(n), 0.f);
  } else if (count_n != n) {
    fail("densify: step statistics hold {} Gaussians, the view {}", n, count_n);
  }
  const float sx = 0.5f * W, sy = 0.5f * H;
  float *nr = norm(), *ct = count(), *mr = max_radius();
#pragma omp parallel for simd schedule(static)
  for (int i = 0; i < n; ++i) {
    if (radii[i] <= 0) continue;
    float gx = g[2 * i] * sx, gy = g[2 * i + 1] * sy;
    nr[i] += std::sqrt(gx * gx + gy * gy);
    ct[i] += 1.f;
    mr[i] = std::max(mr[i], float(radii[i]));
  }
}

void DensifyStats::add(const StepStats& s) {
  const int n = int(count.size());
  if (s.n != n) fail("densify: statistics hold {} Gaussians, the step {}", n, s.n);
  const float *nr = s.norm(), *ct = s.count(), *mr = s.max_radius();
#pragma omp parallel for simd schedule(static)
  for (int i = 0; i < n; ++i) {
    if (ct[i] <= 0) continue;  // visible in none of the step's views
    grad_accum[i] += nr[i];
    count[i] += int(ct[i]);
    max_radius[i] = std::max(max_radius[i], mr[i]);
  }
}

namespace {

// Applies the row gather to the model, Adam and the max-radius statistic (fresh rows get radius 0).
void gather_all(GaussianModel& model, Adam& adam, DensifyStats& stats, const std::vector<int>& src,
                const std::vector<char>& fresh) {
  model.gather(src);
  adam.gather(src, fresh);
  std::vector<float> r(src.size(), 0.f);
  for (size_t i = 0; i < src.size(); ++i)
    if (fresh.empty() || !fresh[i]) r[i] = stats.max_radius[src[i]];
  stats.max_radius.swap(r);
  stats.grad_accum.assign(src.size(), 0.f);
  stats.count.assign(src.size(), 0);
}

float max_scale(const GaussianModel& m, int i) {
  const float* s = m.log_scale.data() + size_t(i) * 3;
  return std::exp(std::max(s[0], std::max(s[1], s[2])));
}

}  // namespace

int prune_gaussians(GaussianModel& model, Adam& adam, DensifyStats& stats, const std::vector<char>& mask) {
  std::vector<int> keep;
  keep.reserve(model.n);
  for (int i = 0; i < model.n; ++i)
    if (!mask[i]) keep.push_back(i);
  int removed = model.n - int(keep.size());
  if (removed == 0) return 0;
  std::vector<float> acc(keep.size()), rad(keep.size());
  std::vector<int> cnt(keep.size());
  for (size_t i = 0; i < keep.size(); ++i) {
    acc[i] = stats.grad_accum[keep[i]];
    cnt[i] = stats.count[keep[i]];
    rad[i] = stats.max_radius[keep[i]];
  }
  model.gather(keep);
  adam.gather(keep, {});
  stats.grad_accum.swap(acc);
  stats.count.swap(cnt);
  stats.max_radius.swap(rad);
  return removed;
}

DensifyResult densify_and_prune(GaussianModel& model, Adam& adam, DensifyStats& stats, const DensifyConfig& cfg,
                                float extent, float screen_limit, std::mt19937_64& rng) {
  DensifyResult res;
  const int n0 = model.n;
  if (int(stats.count.size()) != n0)
    fail("densify: statistics hold {} Gaussians, the model {}", stats.count.size(), n0);
  std::vector<char> clone(n0, 0), split(n0, 0);
  for (int i = 0; i < n0; ++i) {
    float g = stats.count[i] > 0 ? stats.grad_accum[i] / float(stats.count[i]) : 0.f;
    if (!(g >= cfg.grad_threshold)) continue;
    if (max_scale(model, i) <= cfg.percent_dense * extent) clone[i] = 1;
    else split[i] = 1;
  }
  std::vector<int> src;
  std::vector<char> fresh;
  src.reserve(n0 + n0 / 4);
  for (int i = 0; i < n0; ++i)
    if (!split[i]) src.push_back(i), fresh.push_back(0);
  for (int i = 0; i < n0; ++i)
    if (clone[i]) src.push_back(i), fresh.push_back(1), ++res.cloned;
  std::vector<int> split_idx;
  for (int i = 0; i < n0; ++i)
    if (split[i]) split_idx.push_back(i);
  res.split = int(split_idx.size());
  const size_t child0 = src.size();
  for (int c = 0; c < cfg.split_children; ++c)
    for (int i : split_idx) src.push_back(i), fresh.push_back(1);
  if (res.cloned || res.split) {
    gather_all(model, adam, stats, src, fresh);
    // Children: centre sampled from the parent Gaussian N(mean, R diag(s^2) R^T), scale / 1.6.
    std::normal_distribution<float> nd(0.f, 1.f);
    const float dlog = std::log(cfg.split_scale_div);
    for (size_t r = child0; r < src.size(); ++r) {
      float* mu = model.mean.data() + r * 3;
      float* ls = model.log_scale.data() + r * 3;
      const float* q = model.quat.data() + r * 4;
      float qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      float w = q[0] / qn, x = q[1] / qn, y = q[2] / qn, z = q[3] / qn;
      float R[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                    2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                    2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
      float s[3];
      for (int a = 0; a < 3; ++a) s[a] = std::exp(ls[a]) * nd(rng);
      for (int a = 0; a < 3; ++a) mu[a] += R[a * 3] * s[0] + R[a * 3 + 1] * s[1] + R[a * 3 + 2] * s[2];
      for (int a = 0; a < 3; ++a) ls[a] -= dlog;
    }
  }
  res.pruned = prune_step(model, adam, stats, cfg, extent, screen_limit).pruned;
  return res;
}

DensifyResult prune_step(GaussianModel& model, Adam& adam, DensifyStats& stats, const DensifyConfig& cfg, float extent,
                         float screen_limit) {
  if (int(stats.max_radius.size()) != model.n)
    fail("densify: statistics hold {} Gaussians, the model {}", stats.max_radius.size(), model.n);
  std::vector<char> prune(model.n, 0);
  for (int i = 0; i < model.n; ++i) {
    bool p = sigmoid(model.opacity_logit[i]) < cfg.min_opacity;
    if (screen_limit > 0)
      p = p || stats.max_radius[i] > screen_limit || max_scale(model, i) > cfg.max_world_scale * extent;
    prune[i] = p;
  }
  DensifyResult res;
  res.pruned = prune_gaussians(model, adam, stats, prune);
  stats.reset(model.n);
  return res;
}

void reset_opacity(GaussianModel& model, Adam& adam, float max_opacity) {
  const float cap = inverse_sigmoid(max_opacity);
  for (auto& o : model.opacity_logit) o = std::min(o, cap);
  adam.reset_moments("opacity");
}

}  // namespace hgs::train
