// Sparse channel groups (ChannelsT::num_groups, rasterize.h): a Gaussian adds its value rows to its own groups
// only. Checked against the dense extra channels they stand for (the dense path has its own brute-force and
// finite-difference tests): a scene whose Gaussians have 0 to 3 entries in G groups renders the same groups as the
// dense [N, G * GW] channels with zeros elsewhere, and its backward gives the same group-value gradients (the
// gradient-free tail of each group zero) and the same gradients of the Gaussians, in double and float, with the
// upstream group gradients read through a row and group stride. Finite differences of the whole chain in double
// through the group values and the Gaussians' parameters.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <tuple>
#include <type_traits>

#include "core/error.h"
#include "fd_check.h"
#include "render/raster_isa.h"
#include "render/renderer.h"
#include "render_ref.h"
#include "render_run.h"

namespace hgs::render::test {
namespace {

using namespace hgs::test;

constexpr int kG = 5, kGW = 4, kGWg = 3;  // groups, channels per group, channels with gradient

// Entries of every Gaussian: 0..3 distinct groups in ascending order, values N(0, 1).
struct Groups {
  std::vector<int> ptr{0}, id;
  std::vector<double> val;
  // 0 to max_entries entries per Gaussian.
  explicit Groups(int n, uint32_t seed, int max_entries = 3) {
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> cnt(0, max_entries);
    std::normal_distribution<double> N01(0, 1);
    for (int i = 0; i < n; ++i) {
      std::vector<int> g(kG);
      for (int k = 0; k < kG; ++k) g[k] = k;
      std::shuffle(g.begin(), g.end(), rng);
      g.resize(cnt(rng));
      std::sort(g.begin(), g.end());
      for (int k : g) {
        id.push_back(k);
        for (int c = 0; c < kGW; ++c) val.push_back(N01(rng));
      }
      ptr.push_back(int(id.size()));
    }
  }
  template <class T>
  ChannelsT<T> channels(const T* values) const {  // values [E, GW]
    ChannelsT<T> ch;
    ch.num_groups = kG;
    ch.group_width = kGW;
    ch.group_ptr = ptr.data();
    ch.group_id = id.data();
    ch.group_val = values;
    return ch;
  }
  std::vector<double> dense(int n) const {  // [N, G * GW]
    std::vector<double> d(size_t(n) * kG * kGW, 0.0);
    for (int i = 0; i < n; ++i)
      for (int e = ptr[i]; e < ptr[i + 1]; ++e)
        for (int c = 0; c < kGW; ++c) d[(size_t(i) * kG + id[e]) * kGW + c] = val[size_t(e) * kGW + c];
    return d;
  }
};

template <class T>
std::vector<T> conv(const std::vector<double>& v) {
  return std::vector<T>(v.begin(), v.end());
}

// Renders the scene once with the groups and once with the equivalent dense channels, backward with the same
// upstream gradients (the groups' read from a strided layout, or a contiguous one as the hybrid method's), and
// compares. The 69-pixel-wide variant has batches past the image edge.
template <class T>
void check_against_dense(double tol, bool contiguous = false, int width = 64, int height = 48) {
  Scene s = random_scene(400, width, height, 91, 0.9, 0);
  const Groups gr(s.n, 17);
  const std::vector<T> val = conv<T>(gr.val), dense = conv<T>(gr.dense(s.n));
  const size_t P = size_t(s.cam.width) * s.cam.height;
  std::mt19937 rng(3);
  const std::vector<T> wr = conv<T>(random_weights(3 * P, rng)), wa = conv<T>(random_weights(P, rng));
  // Upstream group gradients: group g, channel i at [p * 23 + g * 4 + i + 1] (a wider layout) or at
  // [p * 15 + g * 3 + i] (contiguous); the dense equivalent has them at [p, g * 4 + i] and 0 in the gradient-free
  // channel.
  const int row = contiguous ? kG * kGWg : 23, gstride = contiguous ? kGWg : 4, off = contiguous ? 0 : 1;
  const std::vector<T> wide = conv<T>(random_weights(P * row, rng));
  std::vector<T> wd(P * kG * kGW, T(0));
  for (size_t p = 0; p < P; ++p)
    for (int g = 0; g < kG; ++g)
      for (int i = 0; i < kGWg; ++i) wd[(p * kG + g) * kGW + i] = wide[p * row + g * gstride + i + off];

  std::vector<std::vector<T>> store;
  RendererT<T> rs, rd;
  RenderOutputsT<T> os, od;
  ProjectedGradsT<T> ps, pd;
  rs.preprocess(s.cam, s.inputs<T>(store));
  rd.preprocess(s.cam, s.inputs<T>(store));
  rs.composite(gr.channels(val.data()), s.settings, os);
  rd.composite(ChannelsT<T>{dense.data(), kG * kGW}, s.settings, od);
  EXPECT_LE(max_abs_diff(os.groups, od.extra), tol * max_abs(od.extra));
  EXPECT_GT(max_abs(os.groups), 0.1);  // the groups were rendered
  EXPECT_EQ(os.rgb, od.rgb);
  EXPECT_EQ(os.alpha, od.alpha);

  OutputGradsT<T> ds, dd;
  ds.rgb = dd.rgb = wr.data();
  ds.alpha = dd.alpha = wa.data();
  ds.groups = wide.data() + off;
  ds.group_row = row;
  ds.group_stride = gstride;
  ds.group_grad_channels = kGWg;
  dd.extra = wd.data();
  rs.composite_backward(ds, ps);
  rd.composite_backward(dd, pd);
  // Group-value gradients against the dense channels' at the entries; the gradient-free channel is 0.
  ASSERT_EQ(ps.group_val.size(), val.size());
  double worst = 0, scale = max_abs(pd.extra);
  for (int i = 0; i < s.n; ++i)
    for (int e = gr.ptr[i]; e < gr.ptr[i + 1]; ++e)
      for (int c = 0; c < kGW; ++c) {
        const double a = ps.group_val[size_t(e) * kGW + c];
        if (c >= kGWg) EXPECT_EQ(a, 0.0);
        else worst = std::max(worst, std::abs(a - double(pd.extra[(size_t(i) * kG + gr.id[e]) * kGW + c])));
      }
  EXPECT_LE(worst, tol * scale);
  EXPECT_GT(scale, 0.1);
  for (auto [a, b] : {std::pair{&ps.mean2d, &pd.mean2d},
                      {&ps.conic, &pd.conic},
                      {&ps.opacity, &pd.opacity},
                      {&ps.colors, &pd.colors},
                      {&ps.depth, &pd.depth}})
    EXPECT_LE(max_abs_diff(*a, *b), tol * (max_abs(*b) + 1e-30));
}

TEST(RenderGroups, MatchDenseChannelsDouble) { check_against_dense<double>(1e-12); }
TEST(RenderGroups, MatchDenseChannelsFloat) { check_against_dense<float>(2e-5); }
TEST(RenderGroups, MatchDenseChannelsContiguousGradientsAtTheImageEdgeFloat) {
  check_against_dense<float>(2e-5, true, 69, 50);
}
TEST(RenderGroups, MatchDenseChannelsContiguousGradientsAtTheImageEdgeDouble) {
  check_against_dense<double>(1e-12, true, 69, 50);
}

// Finite differences (double) of L = <w_rgb, rgb> + <w_groups, groups> with respect to the group values, the
// means and the opacity logits, through preprocess, composite and both backward phases.
TEST(RenderGroups, FiniteDifferences) {
  SingleThread one_thread;
  Scene s = random_scene(60, 40, 36, 57, 0.9, 0);
  Groups gr(s.n, 5);
  const size_t P = size_t(s.cam.width) * s.cam.height;
  std::mt19937 rng(11);
  const std::vector<double> wr = random_weights(3 * P, rng), wg = random_weights(P * kG * kGW, rng);
  RendererT<double> r;
  RenderOutputsT<double> out;
  std::vector<std::vector<double>> store;
  auto run = [&]() {
    r.preprocess(s.cam, s.inputs<double>(store));
    r.composite(gr.channels(gr.val.data()), s.settings, out);
    Eval e;
    e.loss = dot(wr, out.rgb) + dot(wg, std::vector<double>(out.groups.begin(), out.groups.end()));
    e.signature = ref_render(s).signature;
    return e;
  };
  run();
  OutputGradsT<double> d;
  d.rgb = wr.data();
  d.groups = wg.data();
  d.group_row = kG * kGW;
  d.group_stride = kGW;
  d.group_grad_channels = kGW;  // every channel differentiated here
  ProjectedGradsT<double> pg;
  r.composite_backward(d, pg);
  GaussianGradsT<double> g;
  r.preprocess_backward(pg, g);
  const std::vector<double> dval = pg.group_val;
  const FdStats sv = fd_check("group values", gr.val, all_indices(gr.val.size()), dval, run);
  EXPECT_GT(sv.nonzero, 20);
  fd_check("group mean", s.mean, all_indices(s.mean.size()), g.mean, run);
  fd_check("group opacity_logit", s.opacity_logit, all_indices(s.opacity_logit.size()), g.opacity_logit, run);
}

// Upstream group gradients on demand (OutputGradsT::group_rows) from the same [H, W, G * GW] values.
template <class T>
struct GroupRowsFromBuffer {
  const T* values = nullptr;  // [H, W, G * GW]
  int width = 0;
  std::atomic<long>* calls = nullptr;
  static void rows(const void* ctx, int g, int y, int x0, int n, T* out) {
    const auto& c = *static_cast<const GroupRowsFromBuffer*>(ctx);
    c.calls->fetch_add(1);
    for (int l = 0; l < n; ++l)
      for (int i = 0; i < kGWg; ++i)
        out[l * kGWg + i] = c.values[(size_t(y) * c.width + x0 + l) * kG * kGW + size_t(g) * kGW + i];
  }
};

// Preprocesses the scene and composites the groups with the scene's 4 dense channels (the hybrid method's base
// render) into out (planes: ChannelsT::group_planes; live_tiles: group_live_tiles).
template <class T>
void composite_groups_and_base(RendererT<T>& ren, Scene& s, const Groups& gr, const std::vector<T>& val,
                               const std::vector<T>& ex, bool planes, RenderOutputsT<T>& out, bool live_tiles = false) {
  std::vector<std::vector<T>> store;
  ren.preprocess(s.cam, s.inputs<T>(store));
  ChannelsT<T> ch = gr.channels(val.data());
  ch.extra = ex.data();
  ch.num_extra = 4;
  ch.group_planes = planes;
  ch.group_live_tiles = live_tiles;
  ren.composite(ch, s.settings, out);
}

// The two channel paths of the kernels (rasterize.h: visit lists after the walk, or folded into it) sum the same
// terms in the same order: bitwise-equal renders and gradients, with 4 dense channels (the hybrid method's base
// render, the last forward-only), groups of 0 to 3 entries and hard pixel-weight maps, float and double, on a
// width that leaves partial batches. The upstream group gradients read from a buffer or computed on demand
// (group_rows) give the same bits on both paths, and so does a folded backward after a forward that did not fold
// (which builds no channel records: the backward builds them). max_entries above kFoldMaxEntries (4): the folded
// backward sums those Gaussians' group gradients from their visit lists instead of on the stack.
template <class T>
void compare_channel_paths(int max_entries = 3) {
  Scene s = random_scene(700, 69, 50, 23, 0.9, 4);
  s.add_label_weights(3, 6);
  const Groups gr(s.n, 29, max_entries);
  if (max_entries > 4) {  // some Gaussians have more entries than the fold keeps on the stack
    int most = 0;
    for (int i = 0; i < s.n; ++i) most = std::max(most, gr.ptr[i + 1] - gr.ptr[i]);
    ASSERT_GT(most, 4);
  }
  const std::vector<T> val = conv<T>(gr.val), ex = conv<T>(s.extra);
  const size_t P = size_t(s.cam.width) * s.cam.height;
  std::mt19937 rng(7);
  const std::vector<T> wr = conv<T>(random_weights(3 * P, rng)), wa = conv<T>(random_weights(P, rng)),
                       we = conv<T>(random_weights(4 * P, rng)), wg = conv<T>(random_weights(P * kG * kGW, rng)),
                       ww = conv<T>(random_weights(size_t(s.n) * 3, rng));
  struct Run {
    RenderOutputsT<T> out;
    ProjectedGradsT<T> pg;
  };
  std::atomic<long> calls{0};
  const GroupRowsFromBuffer<T> source{wg.data(), s.cam.width, &calls};
  auto run = [&](ChannelPath path, bool on_demand, ChannelPath backward_path) {
    set_raster_channel_path(path);
    Run r;
    RendererT<T> ren;
    composite_groups_and_base(ren, s, gr, val, ex, false, r.out);
    OutputGradsT<T> d;
    d.rgb = wr.data();
    d.alpha = wa.data();
    d.extra = we.data();
    d.extra_grad_channels = 3;
    d.weight_sums = ww.data();
    if (on_demand) {
      d.group_rows = &GroupRowsFromBuffer<T>::rows;
      d.group_ctx = &source;
    } else {
      d.groups = wg.data();
      d.group_row = kG * kGW;
      d.group_stride = kGW;
    }
    d.group_grad_channels = kGWg;
    set_raster_channel_path(backward_path);
    ren.composite_backward(d, r.pg);
    set_raster_channel_path(ChannelPath::kAuto);
    return r;
  };
  const ChannelPath lists = ChannelPath::kVisitLists, folded = ChannelPath::kFolded;
  const Run a = run(lists, false, lists), b = run(folded, false, folded);
  EXPECT_EQ(calls.load(), 0);
  for (bool on_demand : {false, true}) {
    const Run c = run(lists, on_demand, lists), e = run(folded, on_demand, folded), f = run(lists, on_demand, folded);
    for (const Run* r : {&c, &e, &f})
      for (auto [x, y, what] : {std::tuple{&a.pg.mean2d, &r->pg.mean2d, "mean2d"},
                                {&a.pg.conic, &r->pg.conic, "conic"},
                                {&a.pg.opacity, &r->pg.opacity, "opacity"},
                                {&a.pg.colors, &r->pg.colors, "colors"},
                                {&a.pg.extra, &r->pg.extra, "extra"},
                                {&a.pg.group_val, &r->pg.group_val, "group values"}})
        EXPECT_TRUE(bitwise_equal(*x, *y))
            << what << (on_demand ? " on demand" : " from the buffer") << ": max difference " << max_abs_diff(*x, *y);
  }
  EXPECT_GT(calls.load(), 0);
  EXPECT_GT(max_abs(a.out.groups), 0.1);
  EXPECT_GT(max_abs(a.pg.group_val), 0.0);
  EXPECT_GT(max_abs(a.pg.extra), 0.0);
  EXPECT_GT(max_abs(a.out.weight_sums), 0.0);
  for (auto [x, y, what] : {std::tuple{&a.out.rgb, &b.out.rgb, "rgb"},
                            {&a.out.extra, &b.out.extra, "extra image"},
                            {&a.out.weight_sums, &b.out.weight_sums, "weight sums"},
                            {&a.pg.mean2d, &b.pg.mean2d, "mean2d"},
                            {&a.pg.conic, &b.pg.conic, "conic"},
                            {&a.pg.opacity, &b.pg.opacity, "opacity"},
                            {&a.pg.colors, &b.pg.colors, "colors"},
                            {&a.pg.extra, &b.pg.extra, "extra"},
                            {&a.pg.group_val, &b.pg.group_val, "group values"}})
    EXPECT_TRUE(bitwise_equal(*x, *y)) << what << ": max difference " << max_abs_diff(*x, *y);
  EXPECT_TRUE(bitwise_equal(a.out.groups, b.out.groups))
      << "groups image: max difference " << max_abs_diff(a.out.groups, b.out.groups);
}

// The groups as planes (ChannelsT::group_planes: [G, H, W, GW]) hold the bits of the interleaved output
// [H, W, G * GW], on both channel paths, at a width that leaves partial batches; the other outputs are unchanged.
template <class T>
void compare_group_planes() {
  Scene s = random_scene(700, 69, 50, 31, 0.9, 4);
  const Groups gr(s.n, 37);
  const std::vector<T> val = conv<T>(gr.val), ex = conv<T>(s.extra);
  const size_t P = size_t(s.cam.width) * s.cam.height;
  for (ChannelPath path : {ChannelPath::kVisitLists, ChannelPath::kFolded}) {
    set_raster_channel_path(path);
    RenderOutputsT<T> out[2];
    for (bool planes : {false, true}) {
      RendererT<T> ren;
      composite_groups_and_base(ren, s, gr, val, ex, planes, out[planes]);
    }
    set_raster_channel_path(ChannelPath::kAuto);
    const char* what = path == ChannelPath::kFolded ? "folded" : "visit lists";
    ASSERT_EQ(out[1].groups.size(), P * kG * kGW) << what;
    for (size_t p = 0; p < P; ++p)
      for (int g = 0; g < kG; ++g)
        for (int i = 0; i < kGW; ++i)
          ASSERT_EQ(0, std::memcmp(&out[1].groups[(g * P + p) * kGW + i], &out[0].groups[(p * kG + g) * kGW + i],
                                   sizeof(T)))
              << what << ": group " << g << ", channel " << i << ", pixel " << p;
    EXPECT_GT(max_abs(out[1].groups), 0.1) << what;
    EXPECT_TRUE(bitwise_equal(out[0].rgb, out[1].rgb)) << what;
    EXPECT_TRUE(bitwise_equal(out[0].extra, out[1].extra)) << what;
  }
}

// Planes written only where their group has Gaussians (ChannelsT::group_live_tiles): in a tile flagged in
// group_live the plane holds the interleaved output's bits; in one not flagged the interleaved output is +0 and
// the plane's memory (poisoned with NaN before) is not written. Groups that some tiles lack: group 0 holds
// every 16th Gaussian, group 1 every 40th (from the second), group 2 the first three, groups 3 and 4 none.
template <class T>
bool is_plus_zero(T v) {
  return std::bit_cast<std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>>(v) == 0;
}

template <class T>
void compare_live_tiles() {
  Scene s = random_scene(400, 131, 90, 43, 0.9, 4);
  Groups gr(0, 1);
  std::mt19937 rng(5);
  std::normal_distribution<double> N01(0, 1);
  for (int i = 0; i < s.n; ++i) {
    if (i % 16 == 0) gr.id.push_back(0);
    if (i % 40 == 1) gr.id.push_back(1);
    if (i < 3) gr.id.push_back(2);
    gr.ptr.push_back(int(gr.id.size()));
  }
  for (size_t e = 0; e < gr.id.size() * kGW; ++e) gr.val.push_back(N01(rng));
  const std::vector<T> val = conv<T>(gr.val), ex = conv<T>(s.extra);
  const int W = s.cam.width, H = s.cam.height, tx = (W + kTileSize - 1) / kTileSize;
  const int tiles = tx * ((H + kTileSize - 1) / kTileSize);
  const size_t P = size_t(W) * H;
  for (ChannelPath path : {ChannelPath::kVisitLists, ChannelPath::kFolded}) {
    set_raster_channel_path(path);
    RenderOutputsT<T> ref, out;
    RendererT<T> ren;
    composite_groups_and_base(ren, s, gr, val, ex, false, ref);
    out.groups.assign(P * kG * kGW, std::numeric_limits<T>::quiet_NaN());
    composite_groups_and_base(ren, s, gr, val, ex, true, out, true);
    set_raster_channel_path(ChannelPath::kAuto);
    const char* what = path == ChannelPath::kFolded ? "folded" : "visit lists";
    ASSERT_EQ(out.group_live.size(), size_t(kG) * tiles) << what;
    int flagged[kG] = {};
    for (int g = 0; g < kG; ++g)
      for (size_t p = 0; p < P; ++p) {
        const int x = int(p % W), y = int(p / W), t = (y / kTileSize) * tx + x / kTileSize;
        const bool live = out.group_live[size_t(g) * tiles + t];
        if (x % kTileSize == 0 && y % kTileSize == 0) flagged[g] += live;
        for (int i = 0; i < kGW; ++i) {
          const T r = ref.groups[(p * kG + g) * kGW + i], o = out.groups[(g * P + p) * kGW + i];
          if (live) ASSERT_EQ(0, std::memcmp(&r, &o, sizeof(T))) << what << ": group " << g << ", pixel " << p;
          else
            ASSERT_TRUE(is_plus_zero(r) && std::isnan(o))
                << what << ": group " << g << ", pixel " << p << " not flagged holds " << r << ", plane " << o;
        }
      }
    for (int g : {0, 1})
      EXPECT_TRUE(flagged[g] > 0 && flagged[g] < tiles) << what << ": group " << g << " " << flagged[g];
    EXPECT_TRUE(flagged[2] > 0 && flagged[2] < tiles / 2) << what << ": " << flagged[2];
    EXPECT_EQ(flagged[3] + flagged[4], 0) << what;
    EXPECT_TRUE(bitwise_equal(ref.rgb, out.rgb)) << what;
    EXPECT_TRUE(bitwise_equal(ref.extra, out.extra)) << what;
  }
}

TEST(RenderGroups, PlanesHoldTheInterleavedGroupsBitwiseFloat) { compare_group_planes<float>(); }
TEST(RenderGroups, PlanesHoldTheInterleavedGroupsBitwiseDouble) { compare_group_planes<double>(); }
TEST(RenderGroups, LiveTilesHoldThePlanesBitsAndTheOthersAreZeroAndUnwrittenFloat) {
  on_each_isa([] { compare_live_tiles<float>(); });
}
TEST(RenderGroups, LiveTilesHoldThePlanesBitsAndTheOthersAreZeroAndUnwrittenDouble) {
  on_each_isa([] { compare_live_tiles<double>(); });
}

TEST(RenderGroups, LiveTilesWithoutPlanesAreAnError) {
  Scene s = random_scene(50, 40, 30, 3, 0.9, 0);
  const Groups gr(s.n, 5);
  const std::vector<float> val = conv<float>(gr.val);
  std::vector<std::vector<float>> store;
  RendererT<float> ren;
  ren.preprocess(s.cam, s.inputs<float>(store));
  ChannelsT<float> ch = gr.channels(val.data());
  ch.group_live_tiles = true;  // without group_planes
  RenderOutputsT<float> out;
  try {
    ren.composite(ch, s.settings, out);
    ADD_FAILURE() << "no error";
  } catch (const hgs::Error& e) {
    EXPECT_NE(std::string(e.what()).find("group_live_tiles needs group_planes"), std::string::npos) << e.what();
  }
}

TEST(RenderGroups, FoldedAndVisitListPathsAreBitwiseEqualFloat) { compare_channel_paths<float>(); }
TEST(RenderGroups, FoldedAndVisitListPathsAreBitwiseEqualDouble) { compare_channel_paths<double>(); }
TEST(RenderGroups, FoldedBackwardOfGaussiansWithManyEntriesIsBitwiseTheVisitLists) {
  compare_channel_paths<float>(kG);
  compare_channel_paths<double>(kG);
}

}  // namespace
}  // namespace hgs::render::test
