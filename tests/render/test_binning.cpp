// Tile binning against a brute-force reference, at several thread counts: the per-tile lists are the Gaussians
// whose tile rect covers the tile, ordered by (depth, index), and the result does not depend on the thread count.
// Sizes above the parallel paths' threshold (8192 Gaussians) so the chunked prefix sum and the per-thread radix
// passes run.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <random>
#include <tuple>
#include <vector>

#include "render/binning.h"

namespace hgs::render {
namespace {

struct Projected {
  int n = 0;
  std::vector<float> mean2d, conic, opacity, depth;
  std::vector<int> radius;
};

Projected random_projected(int n, int W, int H, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  Projected p;
  p.n = n;
  for (int i = 0; i < n; ++i) {
    p.mean2d.push_back(U(rng) * (W + 40) - 20);
    p.mean2d.push_back(U(rng) * (H + 40) - 20);
    const float sx = 0.5f + 12 * U(rng), sy = 0.5f + 12 * U(rng), rho = 0.8f * (U(rng) - 0.5f);
    const float cxx = sx * sx, cyy = sy * sy, cxy = rho * sx * sy, det = cxx * cyy - cxy * cxy;
    p.conic.insert(p.conic.end(), {cyy / det, -cxy / det, cxx / det});
    p.opacity.push_back(U(rng) < 0.05f ? 0.001f : 0.01f + 0.99f * U(rng));   // some below 1/255: not binned
    p.depth.push_back(U(rng) < 0.1f ? 2.f : 0.2f + 10 * U(rng));             // ties keep index order
    p.radius.push_back(U(rng) < 0.05f ? 0 : int(3 * std::max(sx, sy)) + 1);  // some culled
  }
  return p;
}

Binning bin_at(const Projected& p, int W, int H, int threads) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  Binning b;
  bin_gaussians(W, H, p.n, p.mean2d.data(), p.conic.data(), p.opacity.data(), p.depth.data(), p.radius.data(), b);
  omp_set_num_threads(saved);
  return b;
}

TEST(Binning, TileListsMatchBruteForceAtEveryThreadCount) {
  const int W = 640, H = 480, n = 20000;
  const Projected p = random_projected(n, W, H, 7);
  const Binning ref = bin_at(p, W, H, 1);
  // Brute force from the rects: pair numbering, then per tile the covering Gaussians by (depth, index).
  int total = 0;
  for (int i = 0; i < n; ++i) {
    ASSERT_EQ(ref.pair_offset[i], total) << i;
    const int* tr = &ref.trect[4 * size_t(i)];
    if (tr[0] <= tr[1] && tr[2] <= tr[3]) total += (tr[1] - tr[0] + 1) * (tr[3] - tr[2] + 1);
  }
  ASSERT_EQ(ref.num_pairs, total);
  ASSERT_GT(total, 2 * n / 3);
  for (int t = 0; t < ref.num_tiles; ++t) {
    const int tx = t % ref.tiles_x, ty = t / ref.tiles_x;
    std::vector<std::tuple<float, int, int>> want;  // depth, index, pair
    for (int i = 0; i < n; ++i) {
      const int* tr = &ref.trect[4 * size_t(i)];
      if (tx < tr[0] || tx > tr[1] || ty < tr[2] || ty > tr[3]) continue;
      want.emplace_back(p.depth[i], i, ref.pair_offset[i] + (ty - tr[2]) * (tr[1] - tr[0] + 1) + (tx - tr[0]));
    }
    std::sort(want.begin(), want.end());
    ASSERT_EQ(ref.tile_start[t + 1] - ref.tile_start[t], int(want.size())) << "tile " << t;
    for (size_t k = 0; k < want.size(); ++k) {
      ASSERT_EQ(ref.tile_gauss[ref.tile_start[t] + k], std::get<1>(want[k])) << "tile " << t << " entry " << k;
      ASSERT_EQ(ref.tile_pair[ref.tile_start[t] + k], std::get<2>(want[k])) << "tile " << t << " entry " << k;
    }
  }
  for (int threads : {2, 3, 5}) {
    const Binning b = bin_at(p, W, H, threads);
    EXPECT_EQ(b.pair_offset, ref.pair_offset) << threads << " threads";
    EXPECT_EQ(b.tile_start, ref.tile_start) << threads << " threads";
    EXPECT_EQ(b.tile_gauss, ref.tile_gauss) << threads << " threads";
    EXPECT_EQ(b.tile_pair, ref.tile_pair) << threads << " threads";
    EXPECT_EQ(b.bbox, ref.bbox) << threads << " threads";
  }
}

}  // namespace
}  // namespace hgs::render
