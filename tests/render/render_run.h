// Test helpers shared by the render tests that compare whole renders: a forward + backward of a Scene with
// random upstream gradients, bitwise equality of two arrays, and running a check on each compilation of the
// rasterizer kernels.
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <type_traits>
#include <vector>

#include "fd_check.h"
#include "render/raster_isa.h"
#include "render/renderer.h"
#include "render_ref.h"

namespace hgs::render::test {

// Restores the process-wide rasterizer ISA choice when a test ends.
struct IsaGuard {
  RasterIsa saved = raster_isa();
  ~IsaGuard() { set_raster_isa(saved); }
};

// f() on each compilation of the kernels this CPU runs (AVX2 always, AVX-512 where supported), the choice
// restored afterwards.
template <class F>
void on_each_isa(F&& f) {
  IsaGuard guard;
  for (RasterIsa isa : {RasterIsa::kAvx2, RasterIsa::kAvx512}) {
    if (!raster_isa_supported(isa)) continue;
    SCOPED_TRACE(raster_isa_name(isa));
    set_raster_isa(isa);
    f();
  }
}

// True when a and b hold the same bits. (memcmp of empty vectors would pass null pointers: undefined, UBSan
// reports it.)
// (A and B: std::vector or ScratchVector of the same scalar.)
template <class A, class B>
bool bitwise_equal(const A& a, const B& b) {
  static_assert(std::is_same_v<typename A::value_type, typename B::value_type>);
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(typename A::value_type)) == 0);
}

// The largest |a[i] - b[i]| (a and b expected the same size) and the largest |a[i]|.
template <class A, class B>
double max_abs_diff(const A& a, const B& b) {
  EXPECT_EQ(a.size(), b.size());
  double m = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) m = std::max(m, std::abs(double(a[i]) - double(b[i])));
  return m;
}
template <class A>
double max_abs(const A& a) {
  double m = 0;
  for (auto v : a) m = std::max(m, std::abs(double(v)));
  return m;
}

// Renders s with r into out, then runs the backward of random upstream gradients (from seed) on rgb, alpha,
// depth and extra into g.
template <class T>
void render_with_random_grads(const Scene& s, RendererT<T>& r, RenderOutputsT<T>& out, GaussianGradsT<T>& g,
                              uint32_t seed) {
  std::vector<std::vector<T>> store;
  r.forward(s.cam, s.inputs<T>(store), s.settings, out);
  std::mt19937 rng(seed);
  auto weights = [&](size_t n) {
    std::vector<T> w;
    for (double v : hgs::test::random_weights(n, rng)) w.push_back(T(v));
    return w;
  };
  const std::vector<T> wr = weights(out.rgb.size()), wa = weights(out.alpha.size()), wd = weights(out.depth.size()),
                       we = weights(out.extra.size());
  OutputGradsT<T> d;
  d.rgb = wr.data();
  d.alpha = wa.data();
  d.depth = wd.data();
  d.extra = we.empty() ? nullptr : we.data();
  r.backward(d, g);
}

}  // namespace hgs::render::test
