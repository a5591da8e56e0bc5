// The anchor's support (query::QueryOptions::anchor_support): a label whose Gaussians render nowhere cannot anchor
// an answer once the option asks the anchor to render a fraction of what its mask id covered, however well its
// embedding matches the text. A hand-made model on a tiny synthetic scene: each SfM point a Gaussian labelled with
// its ground-truth object; object 2's visible Gaussians carry a label the masks never use, and mask id 2 is
// carried by a few Gaussians outside every view (the hidden rim of docs/ablation.md, "OF alone on tabletop 7003").
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "core/error.h"
#include "core/image.h"
#include "model/gaussian_model.h"
#include "query/session.h"
#include "scene/scene.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

namespace {

std::vector<float> unit(std::vector<float> v) {
  double s = 0;
  for (float x : v) s += double(x) * x;
  for (float& x : v) x = float(x / std::sqrt(s));
  return v;
}

// Whether p projects inside view v's image (in front of the camera).
bool in_view(const View& v, const Eigen::Vector3f& p) {
  const Eigen::Vector3d c = v.R * p.cast<double>() + v.t;
  if (c.z() <= 1e-6) return false;
  const double x = v.fx * c.x() / c.z() + v.cx, y = v.fy * c.y() / c.z() + v.cy;
  return x > -v.width && y > -v.height && x < 2 * v.width && y < 2 * v.height;  // with a margin of one image
}

// A simple-world scene written to `dir` by `hgs synth` with `args`.
void synth(const fs::path& dir, const std::string& args) {
  const auto r =
      test::run_hgs("synth --world simple --out '" + dir.string() + "' " + args + " --supersample 1 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
}

}  // namespace

TEST(AnchorSupport, AHiddenLabelCannotAnchorTheAnswerWhenTheOptionAsks) {
  test::TempDir tmp;
  const fs::path dir = tmp / "scene";
  ASSERT_NO_FATAL_FAILURE(
      synth(dir, "--views 12 --width 96 --height 72 --objects 3 --points 3000 --noise low --feature-dim 32 --seed 4"));
  auto scene = std::make_shared<Scene>(load_scene(dir));
  const Scene& s = *scene;
  const int K = s.num_objects(), L = K + 2, hidden = 2, visible = K + 1;  // label K+1: in no mask
  ASSERT_GE(K, 2);
  // Each SfM point's object: the ground truth at its projection in the first view that sees it.
  const int n0 = int(s.points.size()), H = 8;
  std::vector<int> obj(n0, 0);
  for (const View& v : s.views) {
    LabelMap gt = load_label_png(dir / "gt" / "instances" / (v.stem + ".png"));
    for (int i = 0; i < n0; ++i) {
      const Eigen::Vector3d c = v.R * s.points[i].cast<double>() + v.t;
      if (obj[i] || c.z() <= 1e-6) continue;
      const int x = int(v.fx * c.x() / c.z() + v.cx), y = int(v.fy * c.y() / c.z() + v.cy);
      if (x >= 0 && y >= 0 && x < gt.width && y < gt.height && gt.at(x, y) <= K) obj[i] = gt.at(x, y);
    }
  }
  ASSERT_GT(std::count(obj.begin(), obj.end(), hidden), 20);
  // H more Gaussians, of label 2, far outside every view: along each axis, the first far point no view sees.
  Eigen::Vector3f far;
  bool found = false;
  for (int a = 0; a < 6 && !found; ++a) {
    far = Eigen::Vector3f::Zero();
    far[a / 2] = a % 2 ? -1e3f : 1e3f;
    found = std::none_of(s.views.begin(), s.views.end(), [&](const View& v) { return in_view(v, far); });
  }
  ASSERT_TRUE(found) << "no far point outside every view";
  std::vector<Eigen::Vector3f> pts = s.points, cols = s.point_colors;
  for (int j = 0; j < H; ++j) {
    pts.push_back(far + Eigen::Vector3f::Constant(float(j)));
    cols.push_back(Eigen::Vector3f::Constant(0.5f));
    obj.push_back(hidden);
  }
  GaussianModel m = init_from_points(pts, cols, 0);
  std::fill(m.opacity_logit.begin(), m.opacity_logit.end(), inverse_sigmoid(0.9f));
  for (int i = n0; i < n0 + H; ++i)
    for (int a = 0; a < 3; ++a) m.log_scale[size_t(i) * 3 + a] = std::log(0.01f);
  // Object 2's visible Gaussians carry label K+1, an embedding near its name's; label 2 carries the name's itself.
  const std::string name = s.object_names.at(hidden), other = s.object_names.at(1);
  const std::vector<float>&e = s.text_embeddings.at(name), &o = s.text_embeddings.at(other);
  const int D = int(e.size());
  std::vector<float> near(D);
  for (int d = 0; d < D; ++d) near[d] = e[d] + 0.3f * o[d];
  near = unit(near);
  m.add_extra("obj", L);
  m.add_extra("obj_id", 1);
  m.add_extra("lang", D);
  ExtraGroup &q = *m.find_extra("obj"), &z = *m.find_extra("obj_id"), &lang = *m.find_extra("lang");
  for (int i = 0; i < m.n; ++i) {
    const int k = (i < n0 && obj[i] == hidden) ? visible : obj[i];
    q.data[size_t(i) * L + k] = 1.f;
    z.data[i] = float(k);
    if (k == 0) continue;
    const std::vector<float>& f = k == visible ? near : k == hidden ? e : s.text_embeddings.at(s.object_names.at(k));
    std::copy(f.begin(), f.end(), lang.data.begin() + size_t(i) * D);
  }
  query::Session session(scene, std::make_shared<const GaussianModel>(m), "", "test model");

  // The counts: mask id 2's pixels in the training views (counted here from the PNGs), nothing rendered of it.
  double mask2 = 0;
  for (int v : s.train_indices()) {
    const auto mk = s.load_mask(v);
    ASSERT_TRUE(mk);
    mask2 += std::count(mk->v.begin(), mk->v.end(), uint16_t(hidden));
  }
  ASSERT_GT(mask2, 0);
  EXPECT_EQ(session.mask_area().at(hidden), mask2);
  EXPECT_EQ(session.mask_area().at(visible), 0.0);
  EXPECT_EQ(session.rendered_area(0.5f).at(hidden), 0.0);
  EXPECT_GT(session.rendered_area(0.5f).at(visible), 0.2 * session.mask_area().at(hidden));

  // Off (the default): label 2 answers, first by cosine and with a valid box, and its mask is empty.
  query::QueryOptions opt;
  opt.fragment_margin = 0;
  const auto off = session.ask(name, opt);
  ASSERT_FALSE(off.chosen.empty());
  EXPECT_EQ(off.chosen[0], hidden);
  const int view = s.test_indices().at(0);
  const eval::Mask empty = session.answer_mask(view, name, opt);
  EXPECT_EQ(std::count(empty.begin(), empty.end(), true), 0);
  // On: label 2 renders 0 of its mask's pixels, so the anchor is the visible label, and the mask is the object's.
  opt.anchor_support = 0.05f;
  EXPECT_EQ(session.ask(name, opt).chosen, (std::vector<int>{visible}));
  const eval::Mask full = session.answer_mask(view, name, opt);
  EXPECT_GT(std::count(full.begin(), full.end(), true), 10);
  // Another object's query keeps its own label either way.
  EXPECT_EQ(session.ask(other, opt).chosen.at(0), 1);
}

TEST(AnchorSupport, WithoutMasksItIsAClearError) {
  test::TempDir tmp;
  const fs::path dir = tmp / "scene";
  ASSERT_NO_FATAL_FAILURE(synth(dir, "--views 8 --width 64 --height 48 --objects 2 --points 1000 --feature-dim 16"));
  fs::remove_all(dir / "masks");
  auto scene = std::make_shared<Scene>(load_scene(dir));
  GaussianModel m = init_from_points(scene->points, scene->point_colors, 0);
  const int D = int(scene->text_embeddings.begin()->second.size());
  m.add_extra("obj", 3);
  m.add_extra("obj_id", 1);
  m.add_extra("lang", D);
  for (int i = 0; i < m.n; ++i) {
    m.find_extra("obj")->data[size_t(i) * 3 + 1 + i % 2] = 1.f;
    m.find_extra("obj_id")->data[i] = float(1 + i % 2);
    m.find_extra("lang")->data[size_t(i) * D] = 1.f;
  }
  query::Session session(scene, std::make_shared<const GaussianModel>(m), "", "test model");
  query::QueryOptions opt;
  opt.anchor_support = 0.1f;
  try {
    session.ask(scene->text_embeddings.begin()->first, opt);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("needs the scene's masks/"), std::string::npos) << e.what();
  }
}
