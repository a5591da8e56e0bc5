// Object-level answers without a scene: object embeddings (eq. of query.h), which objects an answer chooses,
// the opacity each object renders, and the 3D selection used by `hgs export`.
#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "core/half.h"
#include "model/render_inputs.h"
#include "query/query.h"
#include "render/renderer.h"

namespace hgs {
namespace {

// Three Gaussians, L = 3 labels, D = 2: Gaussian 0 in object 1, Gaussian 1 split between objects 1 and 2,
// Gaussian 2 in the background. Positions side by side in front of a camera.
GaussianModel three(bool f16 = false) {
  GaussianModel m;
  m.sh_degree = 0;
  m.resize(3);
  for (int i = 0; i < 3; ++i) {
    m.mean[3 * i] = -0.8f + 0.8f * i;
    m.mean[3 * i + 2] = 3.f;
    for (int a = 0; a < 3; ++a) m.log_scale[3 * i + a] = std::log(0.12f);
    m.opacity_logit[i] = i == 1 ? 0.f : 2.f;  // sigmoid 0.5 for the split one
  }
  m.add_extra("obj", 3).data = {0, 1, 0, /*1*/ 0, 0.25f, 0.75f, /*2*/ 1, 0, 0};
  m.add_extra("obj_id", 1).data = {1, 2, 0};
  const std::vector<float> f = {1, 0, /*1*/ 0, 2, /*2*/ -1, -1};
  ExtraGroup& g = m.add_extra("lang", 2, 0.f, f16);
  if (f16)
    for (size_t k = 0; k < f.size(); ++k) g.half[k] = float_to_half(f[k]);
  else g.data = f;
  return m;
}

render::Camera camera() {
  render::Camera c;
  c.width = 48;
  c.height = 24;
  c.fx = c.fy = 40;
  c.cx = 24;
  c.cy = 12;
  return c;
}

float sig(float x) { return 1.f / (1.f + std::exp(-x)); }

}  // namespace

TEST(ObjectEmbeddings, OpacityAndAssociationWeightedUnitMeans) {
  const query::ObjectEmbeddings oe = query::object_embeddings(three());
  ASSERT_EQ(oe.num_labels, 3);
  ASSERT_EQ(oe.dim, 2);
  // Object 1: sigmoid(2) * (1, 0) + 0.25 * 0.5 * (0, 2), normalised.
  const float a = sig(2.f), b = 0.25f * 0.5f * 2.f, n1 = std::hypot(a, b);
  EXPECT_NEAR(oe.e[2], a / n1, 1e-6);
  EXPECT_NEAR(oe.e[3], b / n1, 1e-6);
  EXPECT_NEAR(oe.weight[1], sig(2.f) + 0.125f, 1e-6);
  // Object 2: only Gaussian 1 -> (0, 1).
  EXPECT_NEAR(oe.e[4], 0.f, 1e-6);
  EXPECT_NEAR(oe.e[5], 1.f, 1e-6);
  EXPECT_NEAR(oe.weight[2], 0.375f, 1e-6);
  // Hard-id counts.
  EXPECT_EQ(oe.count, (std::vector<int>{1, 1, 1}));
}

TEST(ObjectEmbeddings, HalfPrecisionStorageGivesTheSameEmbeddings) {
  const query::ObjectEmbeddings a = query::object_embeddings(three(false)), b = query::object_embeddings(three(true));
  ASSERT_EQ(a.e.size(), b.e.size());
  for (size_t k = 0; k < a.e.size(); ++k) EXPECT_NEAR(a.e[k], b.e[k], 1e-3) << k;
}

TEST(ObjectEmbeddings, NotAHybridModelFailsClearly) {
  GaussianModel m;
  m.resize(1);
  try {
    query::object_embeddings(m);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--method hybrid"), std::string::npos) << e.what();
  }
}

TEST(ChooseObjects, BestOnlyByDefault) {
  const std::vector<query::ObjectScore> s = {{3, 0.9f, 0.7f}, {1, 0.8f, 0.9f}, {2, 0.1f, 0.4f}};
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug"), (std::vector<int>{3}));
}

TEST(ChooseObjects, ThresholdAddsEveryOtherObjectAtOrAboveIt) {
  const std::vector<query::ObjectScore> s = {{3, 0.9f, 0.7f}, {1, 0.8f, 0.9f}, {2, 0.1f, 0.4f}, {4, 0.05f, 0.6f}};
  EXPECT_EQ(query::choose_objects(s, 0.6f, "mug"), (std::vector<int>{3, 1, 4}));  // 0.6 itself is in
  EXPECT_EQ(query::choose_objects(s, 0.95f, "mug"), (std::vector<int>{3}));       // the best even below it
  EXPECT_EQ(query::choose_objects(s, 1e-6f, "mug"), (std::vector<int>{3, 1, 2, 4}));
}

TEST(ChooseObjects, FragmentRuleAddsNearbyLabelsThatAnswerNearlyAsWell) {
  // Labels 1..5 with boxes: 2 overlaps 1, 3 touches 1 within the 20 % growth, 4 is far away, 5 overlaps 1.
  std::vector<query::LabelBox> boxes(6);
  auto box = [&](int k, float x0, float x1) { boxes[k] = {{x0, 0, 0}, {x1, 1, 1}, true}; };
  box(1, 0, 1);
  box(2, 0.5f, 1.5f);
  box(3, 1.3f, 2.3f);  // gap 0.3 < 0.2 + 0.2 (both grown by 20 % of width 1)
  box(4, 5, 6);
  box(5, 0, 1);
  // Cosines: best 0.5, median (of 9) 0.12, so the best leads by 0.38 and margin 0.25 allows 0.095 below the best.
  const std::vector<query::ObjectScore> s = {{1, 0.50f, 0.7f}, {4, 0.49f, 0.6f}, {2, 0.45f, 0.6f},
                                             {3, 0.41f, 0.6f}, {9, 0.12f, 0.6f}, {5, 0.10f, 0.6f},
                                             {8, 0.10f, 0.6f}, {7, 0.08f, 0.6f}, {6, 0.05f, 0.6f}};
  boxes.resize(10);                                                                             // labels 6..9: no box
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.25f, &boxes), (std::vector<int>{1, 2, 3}));  // 4 is elsewhere
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.15f, &boxes), (std::vector<int>{1, 2}));     // 3 is 0.09 below
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.f, &boxes), (std::vector<int>{1}));          // off
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.25f, nullptr), (std::vector<int>{1}));       // no boxes
  // The margin is relative: the same labels with every cosine squeezed 10x towards the median choose the same.
  std::vector<query::ObjectScore> close = s;
  for (auto& c : close) c.cosine = 0.3f + (c.cosine - 0.3f) / 10;
  EXPECT_EQ(query::choose_objects(close, 0.f, "mug", 0.25f, &boxes), (std::vector<int>{1, 2, 3}));
  boxes[2].valid = false;  // too few Gaussians
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.25f, &boxes), (std::vector<int>{1, 3}));
  box(3, 1.5f, 2.5f);  // gap 0.5: apart
  EXPECT_FALSE(query::boxes_meet(boxes[1], boxes[3]));
}

TEST(ChooseObjects, TheAnchorIsTheBestLabelThatHoldsGaussians) {
  // Label 7 ranks first but lost its Gaussians (no valid box); 2 is the best label with Gaussians, 3 its fragment,
  // 4 answers as well but lies elsewhere.
  std::vector<query::LabelBox> boxes(10);
  auto box = [&](int k, float x0, float x1) { boxes[k] = {{x0, 0, 0}, {x1, 1, 1}, true}; };
  box(2, 0, 1);
  box(3, 0.5f, 1.5f);
  box(4, 5, 6);
  box(5, 0, 1);
  box(6, 0, 1);
  const std::vector<query::ObjectScore> s = {{7, 0.60f, 0.9f}, {2, 0.50f, 0.8f}, {4, 0.49f, 0.6f},
                                             {3, 0.45f, 0.6f}, {9, 0.12f, 0.5f}, {5, 0.10f, 0.5f},
                                             {8, 0.10f, 0.5f}, {1, 0.08f, 0.5f}, {6, 0.05f, 0.4f}};
  // Anchor 2 leads the median of the 9 (0.12) by 0.38: margin 0.25 allows 0.095 below 0.50, so 3 joins; 4 is elsewhere.
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.25f, &boxes), (std::vector<int>{2, 3}));
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.f, &boxes), (std::vector<int>{2}));  // the anchor alone
  // min_relevancy still chooses by relevancy, the label without Gaussians included; the anchor stays first.
  EXPECT_EQ(query::choose_objects(s, 0.85f, "mug", 0.f, &boxes), (std::vector<int>{2, 7}));
  // Without boxes, or when no label has one, the best label.
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.25f, nullptr), (std::vector<int>{7}));
  const std::vector<query::LabelBox> none(10);
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.25f, &none), (std::vector<int>{7}));
  // With `anchorable` (the anchor's support, session.h): 2 renders too little of its mask, so 4 anchors, alone
  // (3 is near 2, not near 4); when no label with a box is anchorable, the rule without it.
  std::vector<uint8_t> ok(10, 1);
  ok[2] = 0;
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.25f, &boxes, &ok), (std::vector<int>{4}));
  const std::vector<uint8_t> nobody(10, 0);
  EXPECT_EQ(query::choose_objects(s, 0.f, "mug", 0.25f, &boxes, &nobody), (std::vector<int>{2, 3}));
}

TEST(LabelBoxes, PercentilesOfTheOpaqueGaussiansOfEachLabel) {
  // 101 opaque Gaussians of label 1 at x = 0..100, one transparent Gaussian of label 1 far away, 3 of label 2.
  GaussianModel m;
  m.sh_degree = 0;
  m.resize(105);
  std::vector<float> ids(105, 1.f);
  for (int i = 0; i < 105; ++i) {
    m.mean[3 * i] = float(i);
    m.opacity_logit[i] = 2.f;
  }
  m.mean[3 * 101] = 1e4f;
  m.opacity_logit[101] = -5.f;
  for (int i = 102; i < 105; ++i) ids[i] = 2.f;
  m.add_extra("obj", 3).data.assign(105 * 3, 0.f);
  m.add_extra("obj_id", 1).data = ids;
  m.add_extra("lang", 2).data.assign(105 * 2, 0.f);
  const auto b = query::label_boxes(m, 3);
  ASSERT_TRUE(b[1].valid);
  EXPECT_FLOAT_EQ(b[1].lo[0], 5.f);  // the 5th and 95th percentile of 0..100
  EXPECT_FLOAT_EQ(b[1].hi[0], 95.f);
  EXPECT_FALSE(b[2].valid);  // fewer than 5 Gaussians
  EXPECT_FALSE(b[0].valid);
}

TEST(ChooseObjects, NoObjectIsAClearError) {
  try {
    query::choose_objects({}, 0.f, "red mug");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no foreground objects to answer \"red mug\""), std::string::npos) << e.what();
  }
}

TEST(ObjectOpacity, ChannelsSumToTheRenderedAlphaAndFollowQ) {
  // sum_k A_k = sum_n (sum_k q_{n,k}) alpha T = alpha, pixel by pixel; each A_k is the alpha render with
  // q_{.,k} as the only channel.
  const GaussianModel m = three();
  render::GaussianRenderer r;
  const render::Camera cam = camera();
  const std::vector<float> A = query::render_object_opacity(r, m, cam, {0, 1, 2});
  render::GaussianInputs in = render_inputs(m);
  render::RenderSettings rs;
  render::RenderOutputs out;
  r.forward(cam, in, rs, out);
  const size_t HW = size_t(cam.width) * cam.height;
  ASSERT_EQ(A.size(), HW * 3);
  for (size_t p = 0; p < HW; ++p) ASSERT_NEAR(A[p * 3] + A[p * 3 + 1] + A[p * 3 + 2], out.alpha[p], 1e-5) << p;
  // Centre pixel of Gaussian 1 (x = 24): objects 1 and 2 in the ratio 1 : 3 of its q.
  const size_t c = size_t(12) * cam.width + 24;
  EXPECT_NEAR(A[c * 3 + 2] / A[c * 3 + 1], 3.f, 0.3f);  // its neighbours' tails add a little to object 1
  // Left Gaussian's centre (x = 24 - 0.8 / 3 * 40 ~ 13): object 1 only, nothing of object 2 beyond tails.
  const size_t l = size_t(12) * cam.width + 13;
  EXPECT_GT(A[l * 3 + 1], 0.5f);
  EXPECT_LT(A[l * 3 + 2], 0.05f);
  // Out-of-range labels render nothing.
  const std::vector<float> none = query::render_object_opacity(r, m, cam, {7});
  for (float v : none) ASSERT_EQ(v, 0.f);
}

TEST(SelectObjects, KeepAndRemoveArePartitionsByHardId) {
  const GaussianModel m = three();
  const GaussianModel one = query::select_objects(m, {1}, false), rest = query::select_objects(m, {1}, true);
  ASSERT_EQ(one.n, 1);
  ASSERT_EQ(rest.n, 2);
  EXPECT_EQ(one.mean[0], m.mean[0]);
  EXPECT_EQ(rest.mean[0], m.mean[3]);
  EXPECT_EQ(rest.find_extra("obj_id")->data, (std::vector<float>{2, 0}));
  // Several objects at once; an id no Gaussian has selects nothing (removes nothing).
  EXPECT_EQ(query::select_objects(m, {1, 2}, false).n, 2);
  EXPECT_EQ(query::select_objects(m, {9}, false).n, 0);
  EXPECT_EQ(query::select_objects(m, {9}, true).n, 3);
  // The other fields travel with their Gaussians.
  EXPECT_EQ(one.find_extra("lang")->data, (std::vector<float>{1, 0}));
}

}  // namespace hgs
