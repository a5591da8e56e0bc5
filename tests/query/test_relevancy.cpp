// Pixel-level relevancy of a hybrid model (query::render_relevancy): a rendered language map scored by LERF's
// rule or its cosine with the text: hgs's object-embedding map sum_k A_k e_k (by its cosine, the default, or its
// relevancy; not in the paper), the paper's (raw) map sum_n f_n alpha T, or the raw map weighted by the rendered
// foreground opacity.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include "core/error.h"
#include "eval/protocols.h"
#include "model/render_inputs.h"
#include "query/query.h"
#include "query/relevancy.h"
#include "render/renderer.h"

namespace hgs {
namespace {

// Two opaque Gaussians side by side in front of the camera: the left one in object 1, the right one in the
// background (object 0). Their embeddings are e_d(0) and e_d(1) (unit axes) unless given.
struct TwoBlobs {
  GaussianModel m;
  render::Camera cam;
  static constexpr int D = 4;
  explicit TwoBlobs(float q0_right = 1.f) {
    m.sh_degree = 0;
    m.resize(2);
    for (int i = 0; i < 2; ++i) {
      m.mean[3 * i] = i == 0 ? -0.5f : 0.5f;
      m.mean[3 * i + 2] = 3.f;
      for (int a = 0; a < 3; ++a) m.log_scale[3 * i + a] = std::log(0.15f);
      m.opacity_logit[i] = 4.f;
    }
    ExtraGroup& q = m.add_extra("obj", 2);
    q.data = {0.f, 1.f, q0_right, 1.f - q0_right};
    ExtraGroup& f = m.add_extra("lang", D);
    f.data = {1, 0, 0, 0, 0, 1, 0, 0};
    m.add_extra("obj_id", 1).data = {1.f, q0_right > 0.5f ? 0.f : 1.f};
    cam.width = 64;
    cam.height = 32;
    cam.fx = cam.fy = 60;
    cam.cx = 32;
    cam.cy = 16;
  }
  int left() const { return 16 * cam.width + 22; }   // pixel of the left blob's centre
  int right() const { return 16 * cam.width + 42; }  // ... and of the right one's
};

query::Canonical canonical() {  // two unit directions away from the axes the blobs and texts use
  return {{0, 0, 1, 0}, {0, 0, 0.6f, 0.8f}};
}

TEST(Relevancy, ForegroundVariantSilencesBackgroundGaussians) {
  TwoBlobs s;
  render::GaussianRenderer r;
  const float text_right[TwoBlobs::D] = {0, 1, 0, 0}, text_left[TwoBlobs::D] = {1, 0, 0, 0};
  const auto fg = query::Relevancy::Foreground;
  const std::vector<float> rel_r = query::render_relevancy(r, s.m, s.cam, text_right, canonical(), fg);
  const std::vector<float> rel_l = query::render_relevancy(r, s.m, s.cam, text_left, canonical(), fg);
  ASSERT_EQ(rel_r.size(), size_t(s.cam.width) * s.cam.height);
  // The query that matches the background blob's embedding finds nothing there...
  EXPECT_LT(rel_r[s.right()], 0.01f);
  // ... while the foreground blob's matching query gets LERF's high relevancy (> 0.5) at its centre.
  EXPECT_GT(rel_l[s.left()], 0.5f);
  EXPECT_LT(rel_l[s.right()], 0.01f);
  EXPECT_EQ(rel_l[0], 0.f);  // nothing rendered in the corner
}

TEST(Relevancy, ForegroundBlobKeepsItsRelevancy) {
  // The same right blob as foreground (q_0 = 0): now its embedding answers the query.
  TwoBlobs s(0.f);
  render::GaussianRenderer r;
  const float text_right[TwoBlobs::D] = {0, 1, 0, 0};
  const std::vector<float> rel =
      query::render_relevancy(r, s.m, s.cam, text_right, canonical(), query::Relevancy::Foreground);
  EXPECT_GT(rel[s.right()], 0.9f);  // LERF relevancy of a feature equal to the text (cosine 1 against 0)
  EXPECT_LT(rel[s.left()], 0.6f);   // ... and of an orthogonal one (about 0.5)
}

TEST(Relevancy, LerfVariantIsTheRelevancyOfTheRenderedFeatureAlone) {
  // The published protocol: no foreground weight. The background blob answers the query that matches its
  // embedding, the empty corner (zero feature) gets 0.5 like any tie, and every pixel equals LERF's relevancy
  // of the rendered feature sum_n f_n alpha T computed here by brute force.
  TwoBlobs s;
  render::GaussianRenderer r;
  const float text_right[TwoBlobs::D] = {0, 1, 0, 0};
  const std::vector<float> rel =
      query::render_relevancy(r, s.m, s.cam, text_right, canonical(), query::Relevancy::Lerf);
  EXPECT_GT(rel[s.right()], 0.9f);
  EXPECT_FLOAT_EQ(rel[0], 0.5f);
  render::GaussianInputs in = render_inputs(s.m);
  in.extra = s.m.find_extra("lang")->data.data();
  in.num_extra = TwoBlobs::D;
  render::RenderSettings rs;
  render::RenderOutputs out;
  r.forward(s.cam, in, rs, out);
  for (size_t p = 0; p < rel.size(); ++p)
    ASSERT_NEAR(rel[p], query::lerf_relevancy(&out.extra[p * TwoBlobs::D], text_right, canonical(), TwoBlobs::D), 1e-5)
        << "pixel " << p;
  EXPECT_STREQ(query::relevancy_name(query::Relevancy::Lerf), "lerf");
}

TEST(Relevancy, SeveralTextsFromOneRenderEqualOneRenderEach) {
  // render_relevancies (one render of the language map, T texts) must give exactly what T calls of
  // render_relevancy give, in both variants and in the order of the texts.
  TwoBlobs s;
  render::GaussianRenderer r;
  const float t0[TwoBlobs::D] = {0, 1, 0, 0}, t1[TwoBlobs::D] = {1, 0, 0, 0}, t2[TwoBlobs::D] = {0.6f, 0, 0, 0.8f};
  for (auto variant : {query::Relevancy::Lerf, query::Relevancy::Foreground, query::Relevancy::Objects,
                       query::Relevancy::ObjectsLerf}) {
    const auto maps = query::render_relevancies(r, s.m, s.cam, {t0, t1, t2}, canonical(), variant);
    ASSERT_EQ(maps.size(), 3u);
    const float* texts[3] = {t0, t1, t2};
    for (int t = 0; t < 3; ++t) {
      const std::vector<float> one = query::render_relevancy(r, s.m, s.cam, texts[t], canonical(), variant);
      ASSERT_EQ(maps[t], one) << "text " << t << " variant " << query::relevancy_name(variant);
    }
    EXPECT_NE(maps[0], maps[1]);
  }
}

// Eight overlapping Gaussians with soft associations over 3 labels and random embeddings (D = 5).
struct SoftScene {
  GaussianModel m;
  render::Camera cam;
  static constexpr int N = 8, L = 3, D = 5;
  SoftScene() {
    m.sh_degree = 0;
    m.resize(N);
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    for (int i = 0; i < N; ++i) {
      m.mean[3 * i] = 0.6f * u(rng);
      m.mean[3 * i + 1] = 0.3f * u(rng);
      m.mean[3 * i + 2] = 3.f + 0.5f * u(rng);
      for (int a = 0; a < 3; ++a) m.log_scale[3 * i + a] = std::log(0.2f + 0.05f * u(rng));
      m.opacity_logit[i] = 1.5f * u(rng);
    }
    m.add_extra("obj", L);
    m.add_extra("lang", D);
    m.add_extra("obj_id", 1);
    // References only after the last add_extra, which may reallocate the groups (found by AddressSanitizer).
    ExtraGroup &q = *m.find_extra("obj"), &f = *m.find_extra("lang"), &z = *m.find_extra("obj_id");
    for (int i = 0; i < N; ++i) {
      float w[L], sum = 0;
      for (float& x : w) sum += (x = 0.05f + std::abs(u(rng)));
      for (int k = 0; k < L; ++k) q.data[size_t(i) * L + k] = w[k] / sum;
      for (int d = 0; d < D; ++d) f.data[size_t(i) * D + d] = u(rng);
      z.data[i] = float(std::max_element(w, w + L) - w);
    }
    cam.width = 48;
    cam.height = 24;
    cam.fx = cam.fy = 40;
    cam.cx = 24;
    cam.cy = 12;
  }
};

TEST(Relevancy, ObjectsVariantsScoreTheObjectConditionedMapByBruteForce) {
  // Every pixel equals the cosine of the text with F(p) = sum_k A_k(p) e_k formed explicitly (Objects) and LERF's
  // relevancy of F(p) (ObjectsLerf): A from render_object_opacity over all labels, e_k from object_embeddings. The
  // fast path never forms F (its cosines come from A, E E^T and E t).
  SoftScene s;
  render::GaussianRenderer r;
  const query::Canonical canon = {{0.3f, -0.2f, 0.5f, 0.1f, 0.7f}, {-0.6f, 0.1f, 0.2f, 0.4f, 0.1f}};
  const float text[SoftScene::D] = {0.2f, 0.9f, -0.3f, 0.1f, 0.2f};
  const std::vector<float> cos = query::render_relevancy(r, s.m, s.cam, text, canon);  // default: Objects
  const std::vector<float> rel = query::render_relevancy(r, s.m, s.cam, text, canon, query::Relevancy::ObjectsLerf);
  const query::ObjectEmbeddings oe = query::object_embeddings(s.m);
  const std::vector<float> A = query::render_object_opacity(r, s.m, s.cam, {0, 1, 2});
  const size_t HW = size_t(s.cam.width) * s.cam.height;
  ASSERT_EQ(rel.size(), HW);
  size_t covered = 0;
  std::vector<char> hole(HW);
  float lowest = 1e30f;  // the lowest cosine of a rendered pixel: what Objects gives a pixel where F = 0
  for (size_t p = 0; p < HW; ++p) {
    float F[SoftScene::D] = {};
    for (int k = 0; k < SoftScene::L; ++k)
      for (int d = 0; d < SoftScene::D; ++d) F[d] += A[p * SoftScene::L + k] * oe.e[size_t(k) * SoftScene::D + d];
    hole[p] = std::all_of(F, F + SoftScene::D, [](float v) { return v == 0.f; });
    ASSERT_NEAR(rel[p], query::lerf_relevancy(F, text, canon, SoftScene::D), 2e-5) << "pixel " << p;
    if (!hole[p]) {
      ASSERT_NEAR(cos[p], query::cosine(F, text, SoftScene::D), 2e-5) << "pixel " << p;
      lowest = std::min(lowest, query::cosine(F, text, SoftScene::D));
    }
    covered += A[p * SoftScene::L] + A[p * SoftScene::L + 1] + A[p * SoftScene::L + 2] > 0.1f;
  }
  EXPECT_GT(covered, HW / 4);     // the Gaussians cover much of the image: the comparison is not all ties
  ASSERT_TRUE(hole[0]);           // nothing rendered in the corner
  EXPECT_FLOAT_EQ(rel[0], 0.5f);  // a zero map, a tie
  for (size_t p = 0; p < HW; ++p) {
    if (!hole[p]) continue;
    ASSERT_NEAR(cos[p], lowest, 2e-5) << "pixel " << p;
  }
  // Given the embeddings, the same maps.
  EXPECT_EQ(query::render_relevancy(r, s.m, s.cam, text, canon, query::Relevancy::Objects, &oe), cos);
}

TEST(Relevancy, ObjectsVariantKeepsAHoleFromStretchingLangSplatsNormalisation) {
  // Text-image cosines share an offset (CLIP's sit near 0.2): here the left blob's object scores 0.6 and the right
  // blob's 0.8, and the rest of the view renders nothing. Were a hole scored 0, LangSplat's min-max normalisation
  // would put the left blob at 0.75 of the range and select it with the right one; scored as the lowest rendered
  // pixel, the left blob is the bottom of the range and only the right blob is selected.
  TwoBlobs s;
  render::GaussianRenderer r;
  const float text[TwoBlobs::D] = {0.6f, 0.8f, 0, 0};
  const std::vector<float> cos = query::render_relevancy(r, s.m, s.cam, text, canonical());
  EXPECT_NEAR(cos[s.left()], 0.6f, 1e-4);
  EXPECT_NEAR(cos[s.right()], 0.8f, 1e-4);
  EXPECT_NEAR(cos[0], *std::min_element(cos.begin() + 1, cos.end()), 1e-6);  // the corner: a hole
  EXPECT_GT(cos[0], 0.55f);
  eval::LerfOptions opt;
  opt.box = 1;
  opt.majority = 1;
  const eval::LerfPost post = eval::lerf_postprocess(cos, s.cam.width, s.cam.height, opt);
  EXPECT_TRUE(post.mask[size_t(s.right())]);
  EXPECT_FALSE(post.mask[size_t(s.left())]);
  EXPECT_FALSE(post.mask[0]);
}

TEST(Relevancy, ObjectsVariantGivesAnObjectOneEmbeddingWhateverItsGaussiansCarry) {
  // Both blobs in object 1 with embeddings (1, 1, 0, 0) and (1, -1, 0, 0): their object's embedding is the first
  // axis. The raw map answers the text (0, 1, 0, 0) on the left blob only; the object-embedding map gives both
  // blobs the object's score: LERF's relevancy of the first axis, or its cosine with the text (0).
  TwoBlobs s(0.f);
  ExtraGroup& f = *s.m.find_extra("lang");
  f.data = {1, 1, 0, 0, 1, -1, 0, 0};
  render::GaussianRenderer r;
  const float text[TwoBlobs::D] = {0, 1, 0, 0}, axis[TwoBlobs::D] = {1, 0, 0, 0};
  const auto raw = query::render_relevancy(r, s.m, s.cam, text, canonical(), query::Relevancy::Lerf);
  const auto obj = query::render_relevancy(r, s.m, s.cam, text, canonical(), query::Relevancy::ObjectsLerf);
  const auto cos = query::render_relevancy(r, s.m, s.cam, text, canonical(), query::Relevancy::Objects);
  EXPECT_GT(raw[s.left()] - raw[s.right()], 0.5f);
  const float want = query::lerf_relevancy(axis, text, canonical(), TwoBlobs::D);
  EXPECT_NEAR(obj[s.left()], want, 1e-5);
  EXPECT_NEAR(obj[s.right()], want, 1e-5);
  EXPECT_NEAR(cos[s.left()], 0.f, 1e-6);
  EXPECT_NEAR(cos[s.right()], 0.f, 1e-6);
  EXPECT_GT(query::render_relevancy(r, s.m, s.cam, axis, canonical())[s.right()], 0.999f);  // the object's own axis
}

TEST(Relevancy, ObjectClassScoresClassifyTheObjectsByBruteForce) {
  // 3D-OVS object mode: every class takes its best foreground object, every label no class took (the background
  // 0 too) the class its embedding is closest to, and a class's score at a pixel is the sum of A_k r_k(c) over
  // its labels. Brute force: the choices by explicit argmax of the cosines, the maps from render_object_opacity
  // and lerf_relevancy, for three texts and for one (where every label joins the only class: a part and its
  // whole both count).
  SoftScene s;
  render::GaussianRenderer r;
  const query::Canonical canon = {{0.3f, -0.2f, 0.5f, 0.1f, 0.7f}, {-0.6f, 0.1f, 0.2f, 0.4f, 0.1f}};
  const query::ObjectEmbeddings oe = query::object_embeddings(s.m);
  constexpr int D = SoftScene::D, L = SoftScene::L;
  auto e = [&](int k) { return &oe.e[size_t(k) * D]; };
  float t0[D], t1[D], t2[D];
  for (int d = 0; d < D; ++d) {
    t0[d] = e(1)[d] + e(2)[d] - 2 * e(0)[d];
    t1[d] = -(e(0)[d] + e(1)[d] + e(2)[d]);
    t2[d] = -t0[d];
  }
  const std::vector<float> A = query::render_object_opacity(r, s.m, s.cam, {0, 1, 2});  // [HW, L]
  const size_t HW = size_t(s.cam.width) * s.cam.height;
  for (const std::vector<const float*>& texts :
       {std::vector<const float*>{t0, t1, t2}, std::vector<const float*>{t0}}) {
    const int C = static_cast<int>(texts.size());
    const auto maps = query::object_class_scores(r, s.m, s.cam, oe, texts, canon);
    ASSERT_EQ(maps.size(), size_t(C));
    std::vector<std::pair<int, int>> pairs;  // (label, class)
    std::vector<bool> taken(L, false);
    for (int c = 0; c < C; ++c) {
      int best = 1;
      for (int k = 2; k < L; ++k)
        if (query::cosine(e(k), texts[c], D) > query::cosine(e(best), texts[c], D)) best = k;
      pairs.push_back({best, c});
      taken[best] = true;
    }
    for (int k = 0; k < L; ++k) {
      if (taken[k]) continue;
      int own = 0;
      for (int c = 1; c < C; ++c)
        if (query::cosine(e(k), texts[c], D) > query::cosine(e(k), texts[own], D)) own = c;
      pairs.push_back({k, own});
    }
    size_t covered = 0;
    for (size_t p = 0; p < HW; ++p) {
      std::vector<float> want(C, 0.f);
      for (auto [k, c] : pairs) want[c] += A[p * L + k] * query::lerf_relevancy(e(k), texts[c], canon, D);
      for (int c = 0; c < C; ++c) ASSERT_NEAR(maps[c][p], want[c], 1e-5) << "pixel " << p << " class " << c;
      covered += want[0] > 1e-3f;
    }
    EXPECT_GT(covered, HW / 10);  // the comparison is not all zeros
    if (C == 1) {
      EXPECT_EQ(pairs.size(), 3u);  // the answer, the other object and the background all in the one class
    }
  }
}

TEST(Relevancy, NamesParseBackAndAnUnknownNameFails) {
  for (auto v :
       {query::Relevancy::Objects, query::Relevancy::ObjectsLerf, query::Relevancy::Lerf, query::Relevancy::Foreground})
    EXPECT_EQ(query::parse_relevancy(query::relevancy_name(v)), v);
  try {
    query::parse_relevancy("pixels");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("objects, objects-lerf, lerf or foreground"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace hgs
