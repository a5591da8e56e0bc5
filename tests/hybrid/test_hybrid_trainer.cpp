// The hybrid trainer on a tiny synthetic scene: it runs, its hard ids match the analytic world's ground truth on
// objects and background, the view logits' gradient through the step matches finite differences, OF beats the
// single-view assignment when views rename objects, SCL keeps the table's features out of object embeddings,
// and its objects answer text queries.
#include <gtest/gtest.h>

#include <algorithm>
#include <iterator>
#include <map>
#include <random>
#include <tuple>

#include "core/error.h"
#include "core/half.h"
#include "eval/instances.h"
#include "hybrid/bro.h"
#include "hybrid/method.h"
#include "hybrid/register.h"
#include "model/ply.h"
#include "query/query.h"
#include "render/camera_from_view.h"
#include "scene/scene.h"
#include "synth/synth.h"
#include "synth_options.h"
#include "test_util.h"
#include "train/registry.h"
#include "train/trainer.h"

using namespace hgs;

namespace {

struct Tiny {
  test::TempDir tmp;
  synth::SynthOptions opt;
  Scene scene;
  std::vector<int> train;
  explicit Tiny(const std::string& noise = "low", int objects = 4, uint64_t seed = 3) {
    opt = test::SmallSynth().objects(objects).noise(noise).seed(seed);
    synth::generate(tmp / "s", opt);
    scene = load_scene(tmp / "s");
    train = scene.train_indices();
  }
  // The analytic world the scene was rendered from (synth::generate builds it from the same options).
  synth::World world() const { return synth::make_world(opt.preset, opt.objects, opt.seed); }
  std::unique_ptr<train::Trainer> trainer(const hybrid::HybridConfig& hc, int iters, int densify_every = 0) {
    std::vector<train::TrainView> views;
    for (int i : train)
      views.push_back({scene.views[i].name, render::camera_from_view(scene.views[i]), scene.load_image(i)});
    train::TrainConfig cfg = train::TrainConfig{}.scaled_to(iters);
    cfg.sh_degree = 1;
    if (densify_every > 0) {
      cfg.densify_from = 1;
      cfg.densify_every = densify_every;
      cfg.densify_cfg.grad_threshold = 1e-6f;  // so that clones and splits happen in a few steps
    }
    hybrid::HybridData data = hybrid::load_hybrid_data(scene, train, hc, false);
    GaussianModel m = init_from_points(scene.points, scene.point_colors, 1);
    return std::make_unique<train::Trainer>(cfg, std::move(m), std::move(views), scene_extent(scene, train),
                                            std::make_unique<hybrid::HybridMethod>(hc, std::move(data), cfg.seed));
  }
};

// What the method reports of its last step (train::Method::stats) and the options it trains with.
train::MethodStats stats(const train::Trainer& t) { return t.method().stats(); }
hybrid::HybridConfig hybrid_config(const train::Trainer& t) {
  return hybrid::HybridConfig::from_json(t.method().config());
}
// The view logits, a parameter registered in the trainer's optimiser.
const std::vector<float>& view_logits(const train::Trainer& t) { return *t.adam().find("view_logits")->values().f32; }

// Ground-truth label of every Gaussian from the analytic world the scene was rendered from: in every view of
// the scene (training and held-out), a ray from the camera centre through the Gaussian's centre is cast into
// the world; when its first hit lies within `tol` (metres, along the ray) of the centre, the centre sits on that
// visible surface and the surface's instance (0 = table / floor) votes. The label is the strict majority of the
// votes; -1 when no view sees the centre on a surface (a floater, a centre inside an object) or the votes split
// (contact lines). Exact, unlike projecting into gt/instances PNGs, which cannot tell a visible centre from a
// hidden one. means [N, 3] -> labels [N].
std::vector<int> true_labels(const synth::World& w, const Scene& s, const GaussianModel& m, double tol = 0.01) {
  std::vector<int> out(m.n, -1);
  const int K = static_cast<int>(w.objects.size());
#pragma omp parallel for schedule(dynamic, 64)
  for (int i = 0; i < m.n; ++i) {
    const Eigen::Vector3d c(m.mean[3 * i], m.mean[3 * i + 1], m.mean[3 * i + 2]);
    std::vector<int> votes(K + 1, 0);  // [K + 1]
    int total = 0;
    for (const View& v : s.views) {
      const Eigen::Vector3d o = v.camera_center();
      const double dist = (c - o).norm();
      synth::Hit h;
      if (!w.intersect(o, (c - o) / dist, 1e30, h) || std::abs(h.t - dist) > tol) continue;
      ++votes[w.prims[h.prim].instance];
      ++total;
    }
    const int best = int(std::max_element(votes.begin(), votes.end()) - votes.begin());
    if (total > 0 && 2 * votes[best] > total) out[i] = best;
  }
  return out;
}

// Association accuracy against true_labels: the fraction of object Gaussians (true label k >= 1) whose hard id
// (`obj_id`) is k, and of background Gaussians (true label 0) whose hard id is 0.
struct AssociationAccuracy {
  double fg = 0, bg = 0;
  int n_fg = 0, n_bg = 0, unknown = 0;
};
AssociationAccuracy association_accuracy(const GaussianModel& m, const std::vector<int>& truth) {
  const ExtraGroup* z = m.find_extra("obj_id");
  AssociationAccuracy a;
  int ok_fg = 0, ok_bg = 0;
  for (int i = 0; i < m.n; ++i) {
    const int t = truth[i], id = static_cast<int>(z->data[i]);
    if (t < 0) ++a.unknown;
    else if (t == 0) ++a.n_bg, ok_bg += id == 0;
    else ++a.n_fg, ok_fg += id == t;
  }
  a.fg = a.n_fg ? double(ok_fg) / a.n_fg : 0;
  a.bg = a.n_bg ? double(ok_bg) / a.n_bg : 0;
  return a;
}
AssociationAccuracy association_accuracy(const GaussianModel& m, const Tiny& t) {
  return association_accuracy(m, true_labels(t.world(), t.scene, m));
}

// Rewrites the masks of the given scene views: every object id k becomes (k - 1 + r) mod K + 1 with an offset r
// drawn per view in 1..K-1, a propagation failure that renames every object of the view (the background stays).
void rename_objects(const Tiny& t, const std::vector<int>& views, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const int K = t.opt.objects;
  for (int i : views) {
    const std::filesystem::path& path = *t.scene.views[i].mask_path;
    LabelMap m = load_label_png(path);  // [H, W]
    const int r = std::uniform_int_distribution<int>(1, K - 1)(rng);
    for (uint16_t& l : m.v)
      if (l >= 1 && l <= K) l = static_cast<uint16_t>((l - 1 + r) % K + 1);
    save_label_png(path, m);
  }
}

// Language embeddings of the object Gaussians (true label k >= 1) against the scene's text embeddings: `own` is
// the fraction whose f_n has its highest cosine with object k's class name among every object name and every
// background surface concept ("wooden table", "floor"); `background` the fraction won by a background concept
// (the table's features bled into the object).
struct LanguageAccuracy {
  double own = 0, background = 0;
};
LanguageAccuracy language_accuracy(const GaussianModel& m, const std::vector<int>& truth, const Tiny& t) {
  const synth::World w = t.world();
  std::vector<std::pair<const std::vector<float>*, int>> cands;  // (text embedding [D], label: 0 = background)
  for (const synth::ObjectInfo& o : w.objects) cands.push_back({&t.scene.text_embeddings.at(o.name), o.id});
  std::vector<std::string> seen;
  for (const synth::Primitive& p : w.prims)
    if (p.instance == 0 && std::find(seen.begin(), seen.end(), p.concept_name) == seen.end()) {
      seen.push_back(p.concept_name);
      cands.push_back({&t.scene.text_embeddings.at(p.concept_name), 0});
    }
  const ExtraGroup& g = *m.find_extra("lang");
  const std::vector<float> f = g.to_float();  // [N, D]
  int own = 0, bg = 0, n = 0;
  for (int i = 0; i < m.n; ++i) {
    if (truth[i] < 1) continue;
    ++n;
    double best = -1e30;
    int label = -1;
    for (const auto& [text, l] : cands) {
      double c = 0;  // f_n . e / |e| (|f_n| is common to every candidate)
      double e2 = 0;
      for (int d = 0; d < g.dim; ++d)
        c += double(f[size_t(i) * g.dim + d]) * (*text)[d], e2 += double((*text)[d]) * (*text)[d];
      c /= std::sqrt(e2);
      if (c > best) best = c, label = l;
    }
    own += label == truth[i];
    bg += label == 0;
  }
  return n ? LanguageAccuracy{double(own) / n, double(bg) / n} : LanguageAccuracy{};
}

// Mean rendered object opacity A_k = sum_n q_{n,k} alpha T inside object k's exact (ground-truth) mask eroded by
// `margin` pixels (BRO may move an edge by its band's half-width; fading shows inside), over all views and objects.
double mean_opacity_inside_objects(const GaussianModel& m, const Scene& s, int margin = 0) {
  const auto names = eval::load_object_names(s.root);
  std::vector<int> ks;
  for (auto& [id, name] : names) ks.push_back(id);
  render::GaussianRenderer r;
  double sum = 0, cnt = 0;
  for (const View& v : s.views) {
    const std::vector<float> A = query::render_object_opacity(r, m, render::camera_from_view(v), ks);
    const eval::InstanceLabels gt = eval::load_instance_masks(s.root, v.name, names, v.width, v.height);
    for (size_t j = 0; j < gt.ids.size(); ++j) {
      std::vector<float> in(gt.masks[j].begin(), gt.masks[j].end()), core(in.size());
      hybrid::erode(in.data(), v.height, v.width, 2 * margin + 1, core.data());
      for (size_t p = 0; p < core.size(); ++p)
        if (core[p] > 0) sum += A[p * ks.size() + j], cnt += 1;
    }
  }
  return cnt ? sum / cnt : 0;
}

}  // namespace

TEST(HybridTrainer, LearnsAssociationsAndLanguage) {
  Tiny t;
  hybrid::HybridConfig hc;
  auto tr = t.trainer(hc, 300);
  float first_app = 0, last_app = 0;
  for (int it = 0; it < 300; ++it) {
    train::StepInfo s = tr->step();
    ASSERT_TRUE(std::isfinite(s.loss.total));
    if (it < 20) first_app += stats(*tr).value("app");
    if (it >= 280) last_app += stats(*tr).value("app");
  }
  EXPECT_LT(last_app, 0.7f * first_app) << "object-conditioned loss did not decrease";
  // (The view weights' gradient is checked against finite differences in ViewLogitGradientThroughTheStep.)
  const GaussianModel& m = tr->model();
  ASSERT_TRUE(m.find_extra("obj") && m.find_extra("obj_id") && m.find_extra("lang"));
  // Hard ids against the world's ground truth, objects and background separately.
  const AssociationAccuracy acc = association_accuracy(m, t);
  std::printf("  association accuracy: objects %.4f (%d Gaussians), background %.4f (%d), no label %d\n", acc.fg,
              acc.n_fg, acc.bg, acc.n_bg, acc.unknown);
  // Measured: objects 0.971 (171 Gaussians on objects), background 0.991 (2066), 3123 of 5360 Gaussians without
  // a label (densification's clones and splits off the surfaces). With every training view's mask (and
  // confidence) moved to the next training view (views and masks mixed up), objects fell to 0.112 (background
  // 0.972): the object accuracy guards that the hard ids come from the right views' masks.
  EXPECT_GT(acc.n_fg, 100);
  EXPECT_GT(acc.fg, 0.85);
  EXPECT_GT(acc.bg, 0.95);
  // Each object's aggregated embedding is closest to its own class name among the scene's objects.
  query::ObjectEmbeddings oe = query::object_embeddings(m);
  int right = 0;
  for (auto& [id, name] : t.scene.object_names) {
    const auto& text = t.scene.text_embeddings.at(name);
    int best = -1;
    double bs = -2;
    for (int k = 1; k < oe.num_labels; ++k) {
      double c = 0;
      for (int d = 0; d < oe.dim; ++d) c += oe.e[size_t(k) * oe.dim + d] * text[d];
      if (c > bs) {
        bs = c;
        best = k;
      }
    }
    right += best == id;
  }
  EXPECT_GE(right, 3) << "of 4 objects matched their names";
  // The PLY keeps everything.
  write_model_ply(t.tmp / "m.ply", m);
  GaussianModel back = read_model_ply(t.tmp / "m.ply");
  ASSERT_TRUE(back.find_extra("lang"));
  EXPECT_TRUE(m.find_extra("lang")->f16);  // half precision while training; files hold float32 (exact widening)
  EXPECT_EQ(back.find_extra("lang")->data, m.find_extra("lang")->to_float());
  EXPECT_EQ(back.find_extra("obj")->data, m.find_extra("obj")->data);
}

TEST(HybridTrainer, AblationsRun) {
  Tiny t;
  for (int mask = 0; mask < 8; ++mask) {
    hybrid::HybridConfig hc;
    hc.use_of = mask & 1;
    hc.use_scl = mask & 2;
    hc.use_bro = mask & 4;
    auto tr = t.trainer(hc, 20);
    for (int it = 0; it < 20; ++it) ASSERT_TRUE(std::isfinite(tr->step().total)) << "ablation " << mask;
    if (!hc.use_of) {  // no view weights learned
      const std::vector<float> w = stats(*tr).array("view_weights");
      EXPECT_EQ(w[0], w[1]);
    }
  }
}

TEST(HybridTrainer, CheckpointResumesBitForBit) {
  // The checkpoint holds the view logits, their Adam state, the observation table and the bf16 moments of f:
  // a resumed run continues exactly as the uninterrupted one.
  Tiny t;
  hybrid::HybridConfig hc;
  hc.fusion_every = 7;            // a table rebuild between the checkpoint and the end
  hc.lambda_bro = 0.7f;           // a non-default option: the checkpoint's options are the ones that continue
  auto a = t.trainer(hc, 40, 5);  // densification at 5, 10, 15, 20: the Gaussian count changes
  const int n0 = a->model().n;
  for (int it = 0; it < 12; ++it) a->step();
  EXPECT_NE(a->model().n, n0);
  a->save_checkpoint(t.tmp / "h.ckpt");
  for (int it = 0; it < 10; ++it) a->step();
  hybrid::HybridConfig other;
  auto b = t.trainer(other, 40, 5);
  b->load_checkpoint(t.tmp / "h.ckpt");
  EXPECT_EQ(b->iteration(), 12);
  EXPECT_EQ(hybrid_config(*b).lambda_bro, 0.7f);
  for (int it = 0; it < 10; ++it) b->step();
  EXPECT_EQ(view_logits(*a), view_logits(*b));
  for (const char* g : {"obj", "obj_id"})
    EXPECT_EQ(a->model().find_extra(g)->data, b->model().find_extra(g)->data) << g;
  EXPECT_EQ(a->model().find_extra("lang")->half, b->model().find_extra("lang")->half);
  EXPECT_FALSE(a->model().find_extra("lang")->half.empty());
  EXPECT_EQ(a->model().mean, b->model().mean);
  // A checkpoint trained with SCL cannot continue as the no-SCL ablation (its feature grids were not loaded).
  hybrid::HybridConfig no_scl;
  no_scl.use_scl = false;
  auto c = t.trainer(no_scl, 40);
  try {
    c->load_checkpoint(t.tmp / "h.ckpt");
    FAIL() << "no error";
  } catch (const hgs::Error& e) {
    EXPECT_NE(std::string(e.what()).find("h.ckpt: the checkpoint was trained without --no-scl"), std::string::npos)
        << e.what();
  }
  EXPECT_EQ(c->iteration(), 0);
}

TEST(HybridTrainer, BoundaryLossDoesNotFadeObjectsOnNoisyMasks) {
  // High mask noise (jitter, swaps, misses, merges, low-confidence rims): with eq. 14 as written (a mean over the
  // band, its plain gradient) the objects' rendered opacity inside their true masks (2 px from the edge, BRO's
  // band half-width) falls well below the run without BRO; with the defaults (scale rule and scale-invariant
  // gradient, hybrid/bro.h) BRO lowers it neither there nor over the whole masks by more than the runs' noise.
  // Means over eight scenes: one 300-step run is chaotic (float rounding alone moves a scene's mask opacity by
  // up to 0.05), so the per-scene differences default - off scatter with a standard deviation of about 0.04
  // (measured on these eight scenes with two builds that round the projection differently), and their mean
  // over eight scenes has a standard error of about 0.015: the bound 0.03 is two of them (fewer scenes and a
  // tighter bound fail or pass with the rounding of the build). Eq. 14 as written loses about 0.12 there, far
  // outside the bound.
  struct Opacity {
    double mask = 0, inside = 0;
  };
  const uint64_t seeds[] = {5, 11, 17, 23, 29, 31, 37, 41};
  auto opacity_after = [&](Tiny& t, bool bro, bool fixed) {
    hybrid::HybridConfig hc;
    hc.use_bro = bro;
    hc.bro_scale_invariant = hc.bro_image_norm = fixed;
    auto tr = t.trainer(hc, 300);
    for (int it = 0; it < 300; ++it) tr->step();
    const Opacity o{mean_opacity_inside_objects(tr->model(), t.scene),
                    mean_opacity_inside_objects(tr->model(), t.scene, 2)};
    std::printf("  scene %d, BRO %s: mean object opacity in the true masks %.4f, 2 px inside them %.4f\n",
                int(t.opt.seed), bro ? (fixed ? "default" : "as written") : "off", o.mask, o.inside);
    return o;
  };
  Opacity none, fixed, plain;  // means over the scenes
  for (uint64_t seed : seeds) {
    Tiny t("high", 6, seed);
    for (auto [sum, bro, fix] : {std::tuple{&none, false, true}, {&fixed, true, true}, {&plain, true, false}}) {
      const Opacity o = opacity_after(t, bro, fix);
      sum->mask += o.mask / std::size(seeds);
      sum->inside += o.inside / std::size(seeds);
    }
  }
  std::printf("  means: off %.4f / %.4f, default %.4f / %.4f, as written %.4f / %.4f\n", none.mask, none.inside,
              fixed.mask, fixed.inside, plain.mask, plain.inside);
  EXPECT_GT(fixed.inside, none.inside - 0.03);
  EXPECT_GT(fixed.mask, none.mask - 0.03);
  EXPECT_LT(plain.inside, none.inside - 0.03) << "eq. 14 as written no longer fades objects: revisit hybrid/bro.h";
  EXPECT_LT(plain.mask, none.mask - 0.05);
}

TEST(HybridTrainer, SemanticLossMovesGeometryOnlyWhenAsked) {
  // With only the SCL loss (eq. 10) in the objective, the default trains f but leaves opacities and centres as
  // they are; sem_geometry = true lets eq. 10 reach them through the pooled weights a_{n,k}.
  Tiny t;
  for (bool geometry : {false, true}) {
    hybrid::HybridConfig hc;
    hc.lambda_rgb = hc.lambda_app = 0.f;
    hc.use_bro = false;
    hc.use_of = false;
    hc.sem_geometry = geometry;
    auto tr = t.trainer(hc, 300);
    const std::vector<float> o0 = tr->model().opacity_logit, m0 = tr->model().mean;
    const std::vector<float> f0 = tr->model().find_extra("lang")->to_float();
    int anchors = 0;
    for (int it = 0; it < 3; ++it) {
      tr->step();
      anchors += int(stats(*tr).value("anchors"));
    }
    ASSERT_GT(anchors, 0);
    EXPECT_NE(tr->model().find_extra("lang")->to_float(), f0) << "f not trained";
    EXPECT_EQ(tr->model().opacity_logit == o0, !geometry);
    EXPECT_EQ(tr->model().mean == m0, !geometry);
  }
}

TEST(MethodRegistry, BuildsTheNamedMethodWithItsOptions) {
  Tiny t;
  hybrid::register_method();
  const auto names = train::method_names();
  ASSERT_GE(names.size(), 2u);
  EXPECT_EQ(names[0], "rgb");
  EXPECT_NE(std::find(names.begin(), names.end(), "hybrid"), names.end());
  train::TrainConfig cfg = train::TrainConfig{}.scaled_to(10);
  cfg.sh_degree = 1;
  hybrid::HybridConfig hc;
  hc.lambda_bro = 0.7f;
  auto tr = train::make_trainer(t.scene, t.train, cfg, "hybrid", hc.to_json(), false);
  EXPECT_EQ(tr->method().name(), "hybrid");
  EXPECT_EQ(hybrid_config(*tr).lambda_bro, 0.7f);
  EXPECT_EQ(tr->views().size(), t.train.size());
  EXPECT_TRUE(hybrid::HybridFields::present(tr->model()));
  EXPECT_EQ(train::make_trainer(t.scene, t.train, cfg, "rgb", nullptr, false)->method().name(), "rgb");
  try {
    train::make_trainer(t.scene, t.train, cfg, "nerf", nullptr, false);
    FAIL() << "no error";
  } catch (const hgs::Error& e) {
    EXPECT_NE(std::string(e.what()).find("unknown training method 'nerf' (known: rgb, hybrid"), std::string::npos)
        << e.what();
  }
}

TEST(HybridConfigJson, RoundTripsAndOlderConfigurationsKeepEq4) {
  hybrid::HybridConfig c;
  c.background_vote = 0.7f;
  c.occlusion_test = false;
  const hybrid::HybridConfig r = hybrid::HybridConfig::from_json(c.to_json());
  EXPECT_EQ(r.background_vote, 0.7f);
  EXPECT_FALSE(r.occlusion_test);
  // A checkpoint written before background_vote existed was trained with eq. 4 as written (and its
  // occlusion_test field is false): resuming it must not switch to the half background vote.
  nlohmann::json old = hybrid::HybridConfig{}.to_json();
  old.erase("background_vote");
  old["occlusion_test"] = false;
  const hybrid::HybridConfig o = hybrid::HybridConfig::from_json(old);
  EXPECT_EQ(o.background_vote, 1.0f);
  EXPECT_FALSE(o.occlusion_test);
  // Today's defaults.
  EXPECT_EQ(hybrid::HybridConfig{}.background_vote, 0.5f);
  EXPECT_TRUE(hybrid::HybridConfig{}.occlusion_test);
}

TEST(HybridTrainer, ViewLogitGradientThroughTheStep) {
  // The view logits' gradient as the trainer's step forms it (q = softmax(s(w)/T) in prepare, object channels
  // composited by the renderer, eq. 6 and SCL's dq, the renderer's backward, the fusion backward, the softmax
  // over views) is the derivative of that step's objective (StepInfo::total): compared with central differences
  // in each logit, every evaluation a fresh step from the same checkpoint (the checkpoint resumes bit for bit:
  // same view, same RNG draws) with one logit moved through the optimiser's own handle on the values. The
  // analytic gradient is read back from Adam's first moment: m_1 = beta1 m_0 + (1 - beta1) g.
  // BRO off: its default gradient is by design not the derivative of its value (bro.h, scale-invariant).
  Tiny t;
  hybrid::HybridConfig hc;
  hc.use_bro = false;
  auto a = t.trainer(hc, 300);
  for (int it = 0; it < 20; ++it) a->step();  // view weights away from uniform, q no longer the initial one
  a->save_checkpoint(t.tmp / "g.ckpt");
  a.reset();
  auto b = t.trainer(hc, 300);
  auto logits = [&]() -> std::vector<float>& { return *b->adam().find("view_logits")->values().f32; };
  b->load_checkpoint(t.tmp / "g.ckpt");
  const int U = static_cast<int>(logits().size());
  ASSERT_EQ(U, int(t.train.size()));
  const std::vector<float> m0 = b->adam().find("view_logits")->m;  // [U]
  const double l0 = b->step().total;
  const std::vector<float> m1 = b->adam().find("view_logits")->m;  // [U]
  const double beta1 = b->adam().beta1;
  std::vector<double> g(U);  // [U] analytic dL/dlogits of the step
  double gmax = 0;
  for (int u = 0; u < U; ++u) {
    g[u] = (double(m1[u]) - beta1 * m0[u]) / (1 - beta1);
    gmax = std::max(gmax, std::abs(g[u]));
  }
  ASSERT_GT(gmax, 0);
  // Tolerance: the objective is summed from float per-pixel terms and carries rounding of ~1e-8, which
  // dominates the difference (measured worst |fd - g| / max|g| over the 14 logits: 2.5e-2, 9.9e-3, 2.5e-3 and
  // 1.2e-3 at h = 1e-3, 3e-3, 1e-2, 3e-2, falling like 1/h, so the O(h^2) truncation is below it at 3e-2).
  // At h = 3e-2 a tolerance of 1e-2 max|g| is 8x the measured error; a sign error, a missing 1/T or 1/(den + eps)
  // or a dropped term of dq in any logit whose gradient exceeds 1 % of the largest one fails.
  const float h = 3e-2f;
  int checked = 0;
  for (int u = 0; u < U; ++u) {
    double f[2], dx[2];
    for (int sgn = 0; sgn < 2; ++sgn) {
      b->load_checkpoint(t.tmp / "g.ckpt");
      const float x = logits()[u];
      logits()[u] = x + (sgn ? -h : h);
      dx[sgn] = double(logits()[u]) - x;  // the step actually taken in float
      f[sgn] = b->step().total;
    }
    const double fd = (f[0] - f[1]) / (dx[0] - dx[1]);
    std::printf("  logit %2d: analytic %+.6e, central difference %+.6e\n", u, g[u], fd);
    EXPECT_NEAR(fd, g[u], 1e-2 * gmax) << "logit " << u;
    checked += std::abs(g[u]) > 0.1 * gmax;
  }
  EXPECT_GE(checked, U / 2) << "most logits should carry a gradient of the order of the largest";
  EXPECT_GT(gmax, 1e-5) << "loss " << l0;
}

TEST(HybridTrainer, SparseAndDenseObjectChannelsGiveTheSameStep) {
  // The object channels as a base render plus sparse per-object groups (the default) and as 4 dense channels per
  // object are the same function (object_groups.h): from the same model, the first step's gradient of every
  // parameter agrees to float rounding, and the first three steps' loss terms agree (full method, SCL and the
  // no-SCL ablation's semantic channels between the groups).
  //
  // The gradients are read from Adam's first moment after the first step (m = (1 - beta1) g), not from the
  // parameters after a few steps: Adam's first update moves each parameter by about lr * sign(g) whatever |g| is,
  // so a gradient made of rounding alone (the rotations of the initial isotropic Gaussians: max |g| ~ 1e-11
  // against 1e-4 for the means) steps in a direction set by rounding, and the two paths' parameters then drift
  // apart (an earlier form of this test compared the parameters after three steps to 1e-4 of their largest; it
  // held on the development machines and failed on an Emerald Rapids guest with 6e-4 against a bound of 2.3e-4,
  // which part of the run rounds differently there was not found). The gradients themselves agree to 1e-7 of their
  // largest value (measured: 0.9-2.1e-7 for the means, scales, opacities and SH, 1e-7 to 6e-7 for the view logits).
  Tiny t;
  for (bool scl : {true, false}) {
    hybrid::HybridConfig hc;
    hc.use_scl = scl;
    hc.sparse_objects = true;
    auto a = t.trainer(hc, 300);
    hc.sparse_objects = false;
    auto b = t.trainer(hc, 300);
    const char* tag = scl ? " SCL" : " no SCL";
    for (int it = 0; it < 3; ++it) {
      const train::StepInfo x = a->step(), y = b->step();
      ASSERT_EQ(x.terms.size(), y.terms.size());
      for (size_t k = 0; k < x.terms.size(); ++k)
        EXPECT_NEAR(x.terms[k].value, y.terms[k].value, 1e-5 * (std::abs(y.terms[k].value) + 1e-3))
            << x.terms[k].name << " step " << it << tag;
      if (it > 0) continue;
      int compared = 0;
      for (const train::AdamParam& pa : a->adam().params) {
        const train::AdamParam* pb = b->adam().find(pa.name);
        ASSERT_NE(pb, nullptr) << pa.name;
        ASSERT_EQ(pa.bf16, pb->bf16) << pa.name;
        std::vector<float> ma = pa.m, mb = pb->m;  // [rows, dim] first moments after one step
        if (pa.bf16) {
          ma.resize(pa.m16.size()), mb.resize(pb->m16.size());
          std::transform(pa.m16.begin(), pa.m16.end(), ma.begin(), bf16_to_float);
          std::transform(pb->m16.begin(), pb->m16.end(), mb.begin(), bf16_to_float);
        }
        ASSERT_EQ(ma.size(), mb.size()) << pa.name;
        double d = 0, m = 0;
        for (size_t i = 0; i < ma.size(); ++i)
          d = std::max(d, double(std::abs(ma[i] - mb[i]))), m = std::max(m, double(std::abs(mb[i])));
        // float32 moments: 1e-4 of the largest (500x the measured rounding); bfloat16 moments hold 8 bits, one
        // unit at the largest value is 2^-8 of it. The absolute floor covers gradients of rounding alone (the
        // rotations, see above).
        const double tol = (pa.bf16 ? 1e-2 : 1e-4) * m + 1e-9;
        EXPECT_LE(d, tol) << pa.name << tag << ": first-step gradients differ (largest |m| " << m << ")";
        compared += m > 1e-7;
      }
      EXPECT_GE(compared, 5) << "means, scales, opacities, SH and the view logits carry gradients" << tag;
    }
    EXPECT_NE(view_logits(*b), std::vector<float>(view_logits(*b).size(), 0.f)) << "the logits moved";
  }
}

TEST(HybridTrainer, ObservationFusionOutvotesViewsThatRenameObjects) {
  // Exact masks (noise none) except that every second training view, the first training view among them,
  // renames every object (rename_objects). The no-OF ablation's single-view assignment (assign.h) takes each
  // Gaussian's id from the first training view that sees it, for nearly every Gaussian a renamed one; OF's vote
  // over the views (eqs. 3-5) keeps the true id, which half of the views agree on while the renamed half spread
  // over the wrong ids. Both rows run the occlusion test (a table rebuild at step 100), so where the first view
  // hides a Gaussian the single-view assignment takes the next view that sees it, often a true one. Measured
  // after 100 steps, seeds 3 / 5 / 7: objects OF 0.996 / 0.984 / 0.978, no OF 0.024 / 0.181 / 0.070; background
  // OF 0.993 / 0.994 / 0.996, no OF 0.974 / 0.991 / 0.987. Guards Observation Fusion as a multi-view vote: with
  // the single-view assignment in both rows, or a fusion that follows one view, the object assertions fail.
  // How many Gaussians the occlusion test sends to a true view depends on the trajectory, which moves with the
  // compiler's rounding: this seed's no-OF objects score 0.18 (321 Gaussians) built with g++ and 0.41 (286) in
  // the clang-14 ThreadSanitizer build, so the no-OF row is bounded against the OF row, not by a fixed level.
  Tiny t("none", 6, 5);
  std::vector<int> renamed;
  for (size_t j = 0; j < t.train.size(); j += 2) renamed.push_back(t.train[j]);
  rename_objects(t, renamed, 5);
  AssociationAccuracy acc[2];  // [no OF, OF]
  for (int of : {0, 1}) {
    hybrid::HybridConfig hc;
    hc.use_of = of;
    auto tr = t.trainer(hc, 100);
    for (int it = 0; it < 100; ++it) tr->step();
    acc[of] = association_accuracy(tr->model(), t);
    std::printf("  OF %s: association accuracy objects %.4f (%d Gaussians), background %.4f (%d)\n", of ? "on " : "off",
                acc[of].fg, acc[of].n_fg, acc[of].bg, acc[of].n_bg);
  }
  ASSERT_GT(acc[1].n_fg, 200);
  EXPECT_GT(acc[1].fg, 0.9);
  EXPECT_LT(acc[0].fg, acc[1].fg - 0.5);    // the vote wins on more than half of the objects' Gaussians
  EXPECT_GT(acc[1].bg, acc[0].bg - 0.005);  // the vote costs the background nothing
}

TEST(HybridTrainer, SclKeepsTheTableOutOfObjectLanguageEmbeddings) {
  // The simulated CLIP features live on a 16-pixel patch grid (6 x 5 patches at 96 x 72), so near every object
  // the upsampled features mix the object with the table around it. The no-SCL ablation fits f to them pixel by
  // pixel and its object Gaussians' f_n take the table's features; SCL pools the references inside each object's
  // mask (eq. 9) and contrasts objects (eq. 10), so f_n of an object's Gaussians points at its own name.
  // Measured after 100 steps (low noise, 6 objects), seeds 3 / 5 / 7: object Gaussians whose f_n is closest to
  // their own name among every object name and background concept: SCL 0.392 / 0.341 / 0.361, no SCL 0.071 /
  // 0.032 / 0.069; closest to a background concept: SCL 0.235 / 0.240 / 0.212, no SCL 0.752 / 0.823 / 0.735.
  // Guards SCL's training of f: with the cosine loss in both rows, or SCL without its gradient to f
  // (lambda_sem = 0: f stays at its random initialisation, ~1/8 right), the assertions fail.
  Tiny t("low", 6, 5);
  LanguageAccuracy acc[2];  // [no SCL, SCL]
  for (int scl : {0, 1}) {
    hybrid::HybridConfig hc;
    hc.use_scl = scl;
    auto tr = t.trainer(hc, 100);
    for (int it = 0; it < 100; ++it) tr->step();
    acc[scl] = language_accuracy(tr->model(), true_labels(t.world(), t.scene, tr->model()), t);
    std::printf("  SCL %s: object Gaussians closest to their own name %.4f, to a background concept %.4f\n",
                scl ? "on " : "off", acc[scl].own, acc[scl].background);
  }
  EXPECT_GT(acc[1].own, 0.25);
  EXPECT_GT(acc[1].own, acc[0].own + 0.2);
  EXPECT_LT(acc[1].background, acc[0].background - 0.3);
}
