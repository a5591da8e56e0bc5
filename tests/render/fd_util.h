// Central finite-difference checker used by the render gradient tests (double precision), and their small helpers
// (random upstream weights, dot product, index lists, a one-thread guard).
// Every perturbation is evaluated together with a decision signature (see render_ref.h); when +h or -h changes
// any discrete decision (alpha crossing 1/255, the 0.99 clamp, the T cut-off, culling, x/y clamping, the SH clamp,
// the tile rect) the finite difference straddles a discontinuity and that coordinate is skipped and counted. The
// test then requires that almost all coordinates were checked.
#pragma once
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <numeric>
#include <random>
#include <string>
#include <vector>

namespace hgs::render::test {

// The finite-difference tests run thousands of tiny renders: one OpenMP thread keeps them fast even on a busy
// machine (multi-threaded results are covered by the determinism test, which checks 1 vs 2 threads bitwise).
struct SingleThread {
  int saved = omp_get_max_threads();
  SingleThread() { omp_set_num_threads(1); }
  ~SingleThread() { omp_set_num_threads(saved); }
};

inline std::vector<double> random_weights(size_t n, std::mt19937& rng) {
  std::normal_distribution<double> N01(0, 1);
  std::vector<double> w(n);
  for (double& v : w) v = N01(rng);
  return w;
}

inline double dot(const std::vector<double>& a, const std::vector<double>& b) {
  double s = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) s += a[i] * b[i];
  return s;
}

inline std::vector<int> all_indices(size_t n) {
  std::vector<int> v(n);
  std::iota(v.begin(), v.end(), 0);
  return v;
}

struct Eval {
  double loss = 0;
  std::vector<int> signature;
};

struct FdStats {
  int checked = 0, skipped = 0, failed = 0;
  double worst = 0;  // worst |fd - an| / (max(|fd|, |an|) + atol)
};

// params: the parameter vector the closure reads; idx: coordinates to check; analytic: dL/dparams (same size).
inline FdStats fd_check(const std::string& name, std::vector<double>& params, const std::vector<int>& idx,
                        const std::vector<double>& analytic, const std::function<Eval()>& eval, double h = 1e-6,
                        double rtol = 1e-5) {
  FdStats st;
  const Eval base = eval();
  double scale = 0;
  for (int i : idx) scale = std::max(scale, std::abs(analytic[i]));
  // absolute floor: a small fraction of the group's largest gradient plus the rounding noise of the difference
  const double atol = 1e-8 * scale + 1e-14 * (std::abs(base.loss) + 1) / h;
  for (int i : idx) {
    const double x = params[i];
    params[i] = x + h;
    const Eval ep = eval();
    params[i] = x - h;
    const Eval em = eval();
    params[i] = x;
    if (ep.signature != base.signature || em.signature != base.signature) {
      ++st.skipped;
      continue;
    }
    ++st.checked;
    const double fd = (ep.loss - em.loss) / (2 * h);
    const double an = analytic[i];
    const double err = std::abs(fd - an);
    const double lim = rtol * std::max(std::abs(fd), std::abs(an)) + atol;
    st.worst = std::max(st.worst, err / (std::max(std::abs(fd), std::abs(an)) + atol));
    if (err > lim) {
      ++st.failed;
      ADD_FAILURE() << name << "[" << i << "]: analytic " << an << " vs finite difference " << fd;
    }
  }
  if (std::getenv("HGS_FD_VERBOSE"))
    std::printf("%-28s checked %4d skipped %3d worst rel err %.2e\n", name.c_str(), st.checked, st.skipped, st.worst);
  EXPECT_GT(st.checked, 0) << name;
  EXPECT_LE(st.skipped * 10, st.checked + st.skipped) << name << ": too many coordinates near a discontinuity";
  return st;
}

}  // namespace hgs::render::test
