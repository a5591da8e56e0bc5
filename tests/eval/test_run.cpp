// The evaluation drivers end to end on a tiny synthetic scene, with the scene's own simulated 2D CLIP
// features standing in for a trained model (a "2D features" baseline) and ground-truth oracles: the protocols
// find the objects, frames and views are matched, reports and PNGs are written.
#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "core/fs.h"
#include "eval/instances.h"
#include "eval/run.h"
#include "query/relevancy.h"  // the LERF rule the "2D features" baseline is scored with
#include "scene/scene.h"
#include "synth/synth.h"
#include "synth_options.h"
#include "test_util.h"

using namespace hgs;
using namespace hgs::eval;
using hgs::query::cosine;
using hgs::query::lerf_relevancy_map;
namespace fs = std::filesystem;

namespace {

struct Fixture {
  hgs::test::TempDir tmp;
  Scene scene;
  std::vector<std::vector<float>> canonical;
  Fixture() {
    // 320x240: LERF's 30x30 box filter and the 16-px feature patches need objects of a realistic pixel size
    // (at 96x72 the 2D baseline is meaningless); D = 256 keeps the random concept vectors nearly orthogonal.
    // Views 0 and 8 are labelled.
    synth::generate(tmp / "scene",
                    hgs::test::SmallSynth().views(9).image_size(320, 240).points(500).feature_dim(256).noise("low"));
    scene = load_scene(tmp / "scene");
    for (const char* c : {"object", "things", "stuff", "texture"}) canonical.push_back(scene.text_embeddings.at(c));
  }
  std::vector<float> features(int view, int& dim) const { return *scene.load_features(view, dim); }
  // The 2D baseline's LERF relevancy of a query on a view's features.
  RelevancyFn feature_relevancy() const {
    return [this](int view, const std::string& q) {
      int dim = 0;
      auto feat = features(view, dim);
      const auto& e = scene.text_embeddings.at(q);
      return lerf_relevancy_map(feat.data(), feat.size() / dim, dim, e.data(), canonical);
    };
  }
};

Fixture& fx() {
  static Fixture f;
  return f;
}

}  // namespace

TEST(EvalRun, LerfOvsWithTwoDFeatures) {
  Fixture& F = fx();
  const RelevancyFn fn = F.feature_relevancy();
  RunOptions opt;
  opt.progress = false;
  opt.overlay_dir = F.tmp / "png";
  EvalReport r = run_lerf_ovs(F.scene, fn, opt);
  size_t expected = 0;
  for (auto& L : load_lerf_labels(F.scene.root)) expected += L.categories.size();
  ASSERT_EQ(r.records.size(), expected);
  ASSERT_GE(expected, 4u);
  EXPECT_EQ(r.records[0].frame, "frame_00001.png");
  const MeanRow s = scene_mean(r);
  std::printf("2D-feature LERF-OVS baseline (320x240, D 256, noise low): mIoU %.3f mBIoU %.3f mAcc %.3f loc %.3f\n",
              s.miou, s.mbiou, s.macc, s.loc_acc);
  // Measured 0.67 / 1.0 on this scene; a sign, scale or alignment error in the pipeline drops these near 0.
  EXPECT_GT(s.miou, 0.5);
  EXPECT_GE(s.loc_acc, 0.75);
  EXPECT_EQ(s.loc_count, expected);
  const fs::path stem = opt.overlay_dir / "frame_00001";
  const std::string q = safe_file_name(r.records[0].query);
  EXPECT_TRUE(fs::exists(stem / (q + ".overlay.png")));
  EXPECT_TRUE(fs::exists(stem / (q + ".heatmap.png")));
  EXPECT_TRUE(fs::exists(stem / (q + ".mask.png")));
  EXPECT_EQ(load_image(stem / (q + ".overlay.png")).width, 320);
  // Wrong-size output from the callback is a clear error.
  RelevancyFn bad = [&](int, const std::string&) { return std::vector<float>(10, 0.f); };
  opt.overlay_dir.clear();
  EXPECT_THROW(run_lerf_ovs(F.scene, bad, opt), hgs::Error);
}

TEST(EvalRun, LerfOvsScaledWindowsAreTheScaledOptionsOnEveryView) {
  // lerf_scaled runs each view with scaled_lerf_options(its width): the same records as the scaled options given
  // by hand (the fixture's views are 320 px wide: box 10, no majority filter), and not those of LangSplat's.
  Fixture& F = fx();
  const RelevancyFn fn = F.feature_relevancy();
  RunOptions scaled, by_hand, fixed;
  scaled.progress = by_hand.progress = fixed.progress = false;
  scaled.lerf_scaled = true;
  by_hand.lerf = scaled_lerf_options(320);
  EXPECT_EQ(by_hand.lerf.box, 10);
  EXPECT_EQ(by_hand.lerf.majority, 1);
  const EvalReport a = run_lerf_ovs(F.scene, fn, scaled), b = run_lerf_ovs(F.scene, fn, by_hand),
                   c = run_lerf_ovs(F.scene, fn, fixed);
  ASSERT_EQ(a.records.size(), b.records.size());
  bool differs = false;
  for (size_t i = 0; i < a.records.size(); ++i) {
    EXPECT_EQ(a.records[i].iou, b.records[i].iou);
    EXPECT_EQ(a.records[i].loc, b.records[i].loc);
    differs |= a.records[i].iou != c.records[i].iou;
  }
  EXPECT_TRUE(differs);
  EXPECT_TRUE(a.extra.contains("lerf_windows"));
  EXPECT_FALSE(c.extra.contains("lerf_windows"));
}

TEST(EvalRun, OraclesScorePerfectlyAndEmptyMasksScoreZero) {
  Fixture& F = fx();
  const auto names = load_object_names(F.scene.root);
  MaskFn oracle = [&](int view, const std::string& q, std::vector<float>*) {
    auto I = load_instance_masks(F.scene.root, F.scene.views[view].name, names);
    for (size_t k = 0; k < I.names.size(); ++k)
      if (I.names[k] == q) return I.masks[k];
    return Mask(I.masks[0].size(), 0);
  };
  RunOptions opt;
  opt.progress = false;
  EvalReport r = run_instances(F.scene, oracle, opt);
  ASSERT_FALSE(r.records.empty());
  for (auto& q : r.records) {
    EXPECT_EQ(q.iou, 1.0);
    EXPECT_EQ(q.biou, 1.0);
    EXPECT_EQ(q.acc, 1.0);
  }
  EXPECT_EQ(scene_mean(r).miou, 1.0);
  MaskFn empty = [&](int view, const std::string&, std::vector<float>*) {
    return Mask(size_t(F.scene.views[view].width) * F.scene.views[view].height, 0);
  };
  EvalReport e = run_lerf_ovs_masks(F.scene, empty, opt);
  ASSERT_FALSE(e.records.empty());
  EXPECT_EQ(scene_mean(e).miou, 0.0);
  EXPECT_LT(scene_mean(e).macc, 1.0);
  EXPECT_EQ(e.mode, "object");
}

TEST(EvalRun, ThreeDOvsWithTwoDFeatures) {
  Fixture& F = fx();
  ClassRelevancyFn fn = [&](int view, const std::vector<std::string>& classes) {
    int dim = 0;
    auto feat = F.features(view, dim);
    const size_t n = feat.size() / dim;
    std::vector<std::vector<float>> out;
    for (auto& c : classes) {
      const auto& e = F.scene.text_embeddings.at(c);
      std::vector<float> m(n);
      for (size_t p = 0; p < n; ++p) m[p] = cosine(&feat[p * dim], e.data(), dim);
      out.push_back(std::move(m));
    }
    return out;
  };
  RunOptions opt;
  opt.progress = false;
  opt.overlay_dir = F.tmp / "png3d";
  EvalReport r = run_3dovs(F.scene, fn, opt);
  ASSERT_EQ(r.records.size(), 2u * 6u);  // 2 labelled views x (4 objects + table + floor)
  ASSERT_EQ(r.frame_accuracy.size(), 2u);
  const MeanRow s = scene_mean(r);
  std::printf("2D-feature 3D-OVS baseline (320x240, D 256, noise low): mIoU %.3f mBIoU %.3f mAcc %.3f\n", s.miou,
              s.mbiou, s.macc);
  // The table and the floor are classes too (as in the real 3D-OVS).
  EXPECT_GT(s.miou, 0.4);  // measured 0.57 (0.33 with the surfaces as background)
  EXPECT_GT(s.macc, 0.0);
  EXPECT_LT(s.macc, 1.0);
  EXPECT_TRUE(fs::exists(opt.overlay_dir / "frame_00001" / "classes.png"));
  EXPECT_TRUE(fs::exists(opt.overlay_dir / "frame_00009" / "classes.png"));
}

TEST(EvalRun, ThreeDOvsCeilingIsWhatTheBestPredictionScores) {
  // 3D-OVS scores a class absent from a frame's ground truth 0 whatever is predicted and gives every unlabelled
  // pixel some class; the report's miou_ceiling is the mean of the frames' best scores (ovs_ceiling, checked by
  // brute force in test_protocols.cpp). The witness: the ground truth with the unlabelled pixels given to a class
  // not in view if there is one (here class 0 in view 0, blanked), else to the largest class. It scores the
  // ceiling exactly; 3d-ovs-labelled scores it 1 on every record and leaves the blanked pair out.
  Fixture& F = fx();
  hgs::test::TempDir tmp;
  fs::copy(F.scene.root, tmp / "scene", fs::copy_options::recursive);
  const OvsLabelSet labels = open_3dovs_labels(tmp / "scene");
  ASSERT_GE(labels.views.size(), 2u);
  {
    const fs::path png = labels.views[0].dir / (labels.classes[0] + ".png");
    Image img = load_image(png, 1);
    std::fill(img.px.begin(), img.px.end(), 0.f);
    save_png(png, img);
  }
  const Scene scene = load_scene(tmp / "scene", {1, false});
  size_t unlabelled = 0;
  ClassRelevancyFn witness = [&](int view, const std::vector<std::string>& classes) {
    for (size_t i = 0; i < labels.views.size(); ++i)
      if (labels.views[i].index == view) {
        const OvsViewLabels gt = load_3dovs_view(labels, i);
        const size_t C = classes.size(), n = gt.masks[0].size();
        size_t to = 0, largest = 0;  // the class the unlabelled pixels go to
        for (size_t c = 0; c < C; ++c) {
          const size_t g = size_t(std::count(gt.masks[c].begin(), gt.masks[c].end(), uint8_t(1)));
          if (g == 0) {
            to = c;
            largest = SIZE_MAX;
          } else if (largest != SIZE_MAX && g > largest) {
            to = c;
            largest = g;
          }
        }
        std::vector<std::vector<float>> out(C);
        for (size_t c = 0; c < C; ++c) out[c].assign(gt.masks[c].begin(), gt.masks[c].end());
        for (size_t p = 0; p < n; ++p)
          if (std::all_of(gt.masks.begin(), gt.masks.end(), [&](const Mask& m) { return m[p] == 0; })) {
            out[to][p] = 0.5f;
            ++unlabelled;
          }
        return out;
      }
    throw Error("no labels for view " + std::to_string(view));
  };
  RunOptions opt;
  opt.progress = false;
  const EvalReport r = run_3dovs(scene, witness, opt);
  ASSERT_GT(unlabelled, 0u);  // the fixture has unlabelled pixels (the sky), so the ceiling is below the share
  const double pairs = double(labels.views.size() * labels.classes.size());
  ASSERT_TRUE(r.extra.contains("miou_ceiling"));
  const double ceiling = r.extra["miou_ceiling"].get<double>();
  EXPECT_LT(ceiling, (pairs - 1) / pairs);
  EXPECT_NEAR(scene_mean(r).miou, ceiling, 1e-12);
  for (const auto& q : r.records) {
    if (q.frame == scene.views[labels.views[0].index].name && q.query == labels.classes[0]) {
      EXPECT_EQ(q.iou, 0.0);
    }
  }
  opt.ovs_scoring = OvsScoring::LabelledOnly;
  const EvalReport l = run_3dovs(scene, witness, opt);
  EXPECT_EQ(l.protocol, "3d-ovs-labelled");
  EXPECT_FALSE(l.extra.contains("miou_ceiling"));
  EXPECT_EQ(l.records.size(), size_t(pairs) - 1);
  for (const auto& q : l.records) EXPECT_EQ(q.iou, 1.0) << q.frame << " " << q.query;
  EXPECT_EQ(scene_mean(l).macc, 1.0);
}

TEST(EvalRun, SafeFileNames) {
  EXPECT_EQ(safe_file_name("red mug"), "red_mug");
  EXPECT_EQ(safe_file_name("a/b\\c"), "a_b_c");
  EXPECT_EQ(safe_file_name(".."), "_..");
  EXPECT_EQ(safe_file_name(""), "_");
  EXPECT_EQ(safe_file_name("tea-cup_2.0"), "tea-cup_2.0");
}

TEST(EvalRun, LabelsThatMatchNoViewAreClearErrors) {
  Fixture& F = fx();
  hgs::test::TempDir tmp;
  fs::copy(F.scene.root, tmp / "scene", fs::copy_options::recursive);
  // A LERF label for a frame the scene does not have.
  atomic_write_text(tmp / "scene/label/frame_00077.json",
                    R"({"info": {"name": "frame_00077.png", "width": 320, "height": 240}, "objects": []})");
  Scene s = load_scene(tmp / "scene");
  RunOptions opt;
  opt.progress = false;
  RelevancyFn zero = [&](int, const std::string&) { return std::vector<float>(320 * 240, 0.f); };
  try {
    run_lerf_ovs(s, zero, opt);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("frame_00077.json: no view of the scene is named frame_00077"), std::string::npos) << msg;
  }
  // A 3D-OVS folder whose view index is past the end of the view list.
  fs::copy(tmp / "scene/segmentations/8", tmp / "scene/segmentations/42", fs::copy_options::recursive);
  ClassRelevancyFn cls = [&](int, const std::vector<std::string>& c) {
    return std::vector<std::vector<float>>(c.size(), std::vector<float>(320 * 240, 0.f));
  };
  try {
    run_3dovs(s, cls, opt);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("view index 42 is out of range (the scene has 9 views)"), std::string::npos) << msg;
  }
  // A callback returning the wrong number of class maps.
  fs::remove_all(tmp / "scene/segmentations/42");
  ClassRelevancyFn few = [&](int, const std::vector<std::string>&) {
    return std::vector<std::vector<float>>(1, std::vector<float>(320 * 240, 0.f));
  };
  EXPECT_THROW(run_3dovs(s, few, opt), Error);
}
