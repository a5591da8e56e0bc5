#include "hybrid/fusion.h"

#include <algorithm>
#include <cmath>

namespace hgs::hybrid {

void apply_confidence(LabelMap& labels, const std::vector<float>& conf, float tau1) {
  if (conf.empty()) return;
  for (size_t i = 0; i < labels.v.size(); ++i)
    if (conf[i] < tau1) labels.v[i] = 0;
}

std::vector<uint8_t> confident_pixels(const std::vector<float>& conf, float tau1) {
  std::vector<uint8_t> ok(conf.size());
  for (size_t i = 0; i < conf.size(); ++i) ok[i] = conf[i] >= tau1;
  return ok;
}

namespace {

// Eq. 3 for one centre in one view: camera-space depth z and, when z > 0 and the projection lies in the image,
// the pixel (ix, iy). Returns false otherwise (V_{n,u} = 0). Shared by observe() and hide_occluded(), which must
// agree on the pixel.
inline bool project_centre(const MaskView& v, const float* c, double& z, int& ix, int& iy) {
  const double X = c[0], Y = c[1], Z = c[2];
  const double* R = v.R;
  z = R[6] * X + R[7] * Y + R[8] * Z + v.t[2];
  if (!(z > 0)) return false;
  const double x = R[0] * X + R[1] * Y + R[2] * Z + v.t[0];
  const double y = R[3] * X + R[4] * Y + R[5] * Z + v.t[1];
  const double px = v.fx * x / z + v.cx, py = v.fy * y / z + v.cy;
  if (!(px >= 0 && py >= 0 && px < v.width && py < v.height)) return false;
  ix = static_cast<int>(px);
  iy = static_cast<int>(py);
  return true;
}

}  // namespace

void hide_occluded(const float* means, int n, const MaskView& v, const float* surface_depth, int u,
                   ObservationTable& table) {
  const int U = table.num_views;
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    uint16_t& l = table.label[size_t(i) * U + u];
    double z;
    int ix, iy;
    if (l == kNoObservation || !project_centre(v, means + 3 * i, z, ix, iy)) continue;
    const float d = surface_depth[size_t(iy) * v.width + ix];
    if (d > 0 && z > d * (1 + kOcclusionTolerance)) l = kNoObservation;
  }
}

void observe(const float* means, int n, const std::vector<MaskView>& views, ObservationTable& table) {
  const int U = static_cast<int>(views.size());
  table.n = n;
  table.num_views = U;
  table.label.assign(size_t(n) * U, kNoObservation);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    for (int u = 0; u < U; ++u) {
      const MaskView& v = views[u];
      double z;
      int ix, iy;
      if (!project_centre(v, means + 3 * i, z, ix, iy)) continue;
      if (!v.observed.empty() && !v.observed[size_t(iy) * v.width + ix]) continue;
      table.label[size_t(i) * U + u] = v.labels.at(ix, iy);
    }
  }
}

std::vector<float> label_evidence(const ObservationTable& tab, int L, int iters, double floor) {
  // Per Gaussian, the count of each observed label (sparse: a Gaussian is seen with few labels).
  std::vector<int> start(size_t(tab.n) + 1, 0);
  std::vector<std::pair<uint16_t, float>> obs;
  {
    std::vector<float> c(L, 0.f);
    for (int n = 0; n < tab.n; ++n) {
      const uint16_t* lab = &tab.label[size_t(n) * tab.num_views];
      for (int u = 0; u < tab.num_views; ++u)
        if (lab[u] < L) c[lab[u]] += 1.f;
      for (int j = 0; j < L; ++j)
        if (c[j] > 0) obs.push_back({uint16_t(j), c[j]}), c[j] = 0.f;
      start[n + 1] = int(obs.size());
    }
  }
  // EM over the Gaussians' unknown labels. post [N, L]; start from the uniform-weight vote of eq. 4.
  std::vector<double> post(size_t(tab.n) * L, 0.0), theta(size_t(L) * L), prior(L);
  for (int n = 0; n < tab.n; ++n) {
    double tot = 0;
    for (int i = start[n]; i < start[n + 1]; ++i) tot += obs[i].second;
    for (int i = start[n]; i < start[n + 1]; ++i) post[size_t(n) * L + obs[i].first] = obs[i].second / tot;
  }
  const double smooth = 1e-2;  // pseudo-count per (k, j): keeps log theta finite for labels never seen together
  for (int it = 0; it <= iters; ++it) {
    // M-step: theta[k][j] from the posterior-weighted counts, prior[k] from the posterior mass.
    std::fill(theta.begin(), theta.end(), smooth);
    std::fill(prior.begin(), prior.end(), smooth);
    for (int n = 0; n < tab.n; ++n) {
      const double* pn = &post[size_t(n) * L];
      for (int k = 0; k < L; ++k) {
        if (pn[k] < 1e-9) continue;
        prior[k] += pn[k];
        for (int i = start[n]; i < start[n + 1]; ++i) theta[size_t(k) * L + obs[i].first] += pn[k] * obs[i].second;
      }
    }
    double ptot = 0;
    for (int k = 0; k < L; ++k) ptot += prior[k];
    for (int k = 0; k < L; ++k) {
      double row = 0;
      for (int j = 0; j < L; ++j) row += theta[size_t(k) * L + j];
      for (int j = 0; j < L; ++j) theta[size_t(k) * L + j] = std::log(theta[size_t(k) * L + j] / row);
      prior[k] = std::log(prior[k] / ptot);
    }
    if (it == iters) break;
    // E-step: post[n][k] proportional to pi_k prod_u theta[k][obs_u].
#pragma omp parallel for schedule(static)
    for (int n = 0; n < tab.n; ++n) {
      if (start[n] == start[n + 1]) continue;
      double* pn = &post[size_t(n) * L];
      double mx = -1e300;
      for (int k = 0; k < L; ++k) {
        double s = prior[k];
        for (int i = start[n]; i < start[n + 1]; ++i) s += obs[i].second * theta[size_t(k) * L + obs[i].first];
        pn[k] = s;
        mx = std::max(mx, s);
      }
      double tot = 0;
      for (int k = 0; k < L; ++k) tot += (pn[k] = std::exp(pn[k] - mx));
      for (int k = 0; k < L; ++k) pn[k] /= tot;
    }
  }
  // Vote table: per observed label j, the log-likelihood of each true label relative to the best one.
  const double lf = std::log(floor);
  std::vector<float> ev(size_t(L) * L);
  for (int j = 0; j < L; ++j) {
    double mx = -1e300;
    for (int k = 0; k < L; ++k) mx = std::max(mx, theta[size_t(k) * L + j]);
    for (int k = 0; k < L; ++k)
      ev[size_t(j) * L + k] = float(1.0 + std::max(theta[size_t(k) * L + j] - mx, lf) / -lf);
  }
  return ev;
}

}  // namespace hgs::hybrid
