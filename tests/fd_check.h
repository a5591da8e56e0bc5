// The finite-difference gradient checker of every test module (double precision, central differences), and its
// small helpers (random upstream weights, dot product, index lists, a one-thread guard).
// Each evaluation may carry a decision signature (see tests/render/render_ref.h); when +h or -h changes any
// discrete decision (alpha crossing 1/255, the 0.99 clamp, the T cut-off, culling, x/y clamping, the SH clamp,
// the tile rect) the finite difference straddles a discontinuity and that coordinate is skipped and counted. The
// check then requires that almost all coordinates were checked. A smooth function returns a plain double and is
// never skipped.
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

namespace hgs::test {

// The finite-difference tests run thousands of tiny evaluations: one OpenMP thread keeps them fast even on a busy
// machine (multi-threaded results are covered by the determinism tests, which compare thread counts bitwise).
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

// 0, step, 2 step, ... below n.
inline std::vector<int> all_indices(size_t n, int step = 1) {
  std::vector<int> v;
  for (size_t i = 0; i < n; i += step) v.push_back(int(i));
  return v;
}

// One evaluation: the loss and the discrete decisions it took.
struct Eval {
  double loss = 0;
  std::vector<int> signature;
};

// Step and tolerance. A coordinate passes when |fd - analytic| <= rtol * max(|fd|, |analytic|) (rtol * |fd| with
// rtol_of_fd) + scale_atol * (largest |analytic| over the checked coordinates) + atol + noise_atol * (|loss| + 1) / h.
// The defaults suit losses of order 1 computed in double precision (the render tests).
struct FdOptions {
  double h = 1e-6;
  double rtol = 1e-5;
  bool rtol_of_fd = false;
  double scale_atol = 1e-8;
  double atol = 0;
  double noise_atol = 1e-14;  // the rounding noise of the difference
  double nonzero_fd = 0;      // |fd| above which a coordinate counts in FdStats::nonzero
};

struct FdStats {
  int checked = 0, skipped = 0, failed = 0;
  int nonzero = 0;          // checked coordinates with |fd| > FdOptions::nonzero_fd
  double worst = 0;         // worst |fd - an| / (max(|fd|, |an|) + the absolute tolerance)
  double max_analytic = 0;  // largest |analytic| over the coordinates
};

// params: the parameter vector the closure reads; idx: coordinates to check; analytic: dL/dparams (same size).
// Reports every failing coordinate, and fails unless some coordinate was checked and at most 10% were skipped.
inline FdStats fd_check(const std::string& name, std::vector<double>& params, const std::vector<int>& idx,
                        const std::vector<double>& analytic, const std::function<Eval()>& eval,
                        const FdOptions& o = {}) {
  FdStats st;
  EXPECT_EQ(params.size(), analytic.size()) << name;
  if (params.size() != analytic.size()) return st;
  const double h = o.h;
  const Eval base = eval();
  for (int i : idx) st.max_analytic = std::max(st.max_analytic, std::abs(analytic[i]));
  double atol = o.scale_atol * st.max_analytic + o.atol;
  if (o.noise_atol != 0) atol += o.noise_atol * (std::abs(base.loss) + 1) / h;
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
    const double lim = o.rtol * (o.rtol_of_fd ? std::abs(fd) : std::max(std::abs(fd), std::abs(an))) + atol;
    st.nonzero += std::abs(fd) > o.nonzero_fd;
    st.worst = std::max(st.worst, err / (std::max(std::abs(fd), std::abs(an)) + atol));
    if (!(err <= lim)) {
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

// A smooth function: no decision signature, no coordinate is skipped.
inline FdStats fd_check(const std::string& name, std::vector<double>& params, const std::vector<int>& idx,
                        const std::vector<double>& analytic, const std::function<double()>& f,
                        const FdOptions& o = {}) {
  return fd_check(name, params, idx, analytic, std::function<Eval()>([&] { return Eval{f(), {}}; }), o);
}

}  // namespace hgs::test
