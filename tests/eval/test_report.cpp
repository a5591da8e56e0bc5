// Report aggregation (per frame / per query / scene means, NaN handling, frame accuracy override), the JSON
// and Markdown writers, the turbo colour map, heatmap and overlay PNGs.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "eval/report.h"
#include "eval/visualize.h"
#include "eval_test_util.h"
#include "test_util.h"

using namespace hgs;
using namespace hgs::eval;
namespace fs = std::filesystem;

namespace {

EvalReport sample() {
  EvalReport r;
  r.protocol = "lerf-ovs";
  r.scene = "toy";
  r.mode = "pixel";
  r.records = {{"f1", "mug", 0.5, 0.25, 0.9, 1},
               {"f1", "plate", 1.0, 0.75, 1.0, 0},
               {"f2", "mug", 0.0, 0.0, 0.8, 1},
               {"f2", "cup | big", 0.3, kNaN, 0.7, -1}};
  return r;
}

}  // namespace

TEST(EvalReport, Means) {
  EvalReport r = sample();
  MeanRow s = scene_mean(r);
  EXPECT_EQ(s.count, 4u);
  EXPECT_DOUBLE_EQ(s.miou, (0.5 + 1.0 + 0.0 + 0.3) / 4);
  EXPECT_DOUBLE_EQ(s.mbiou, (0.25 + 0.75 + 0.0) / 3);  // NaN skipped
  EXPECT_DOUBLE_EQ(s.macc, (0.9 + 1.0 + 0.8 + 0.7) / 4);
  EXPECT_DOUBLE_EQ(s.loc_acc, 2.0 / 3.0);
  EXPECT_EQ(s.loc_count, 3u);
  auto f = frame_means(r);
  ASSERT_EQ(f.size(), 2u);
  EXPECT_EQ(f[0].key, "f1");
  EXPECT_DOUBLE_EQ(f[0].miou, 0.75);
  EXPECT_DOUBLE_EQ(f[1].miou, 0.15);
  EXPECT_DOUBLE_EQ(f[1].loc_acc, 1.0);
  auto q = query_means(r);
  ASSERT_EQ(q.size(), 3u);
  EXPECT_EQ(q[0].key, "mug");
  EXPECT_DOUBLE_EQ(q[0].miou, 0.25);
  EXPECT_EQ(q[0].count, 2u);
  EXPECT_TRUE(std::isnan(q[2].mbiou));
  EXPECT_TRUE(std::isnan(q[2].loc_acc));
  // Frame accuracies (3D-OVS) replace the record mean per frame and for the scene (mean over frames).
  r.frame_accuracy = {{"f1", 0.5}, {"f2", 0.9}};
  EXPECT_DOUBLE_EQ(frame_means(r)[0].macc, 0.5);
  EXPECT_DOUBLE_EQ(scene_mean(r).macc, 0.7);
  EvalReport empty;
  EXPECT_TRUE(std::isnan(scene_mean(empty).miou));
  EXPECT_EQ(scene_mean(empty).count, 0u);
}

TEST(EvalReport, WritesJsonAndMarkdown) {
  hgs::test::TempDir tmp;
  EvalReport a = sample(), b = sample();
  a.records[0].seconds = 0.01;
  a.records[1].seconds = 0.02;
  b.mode = "object";
  b.extra = {{"threshold", 0.4}};
  write_reports(tmp / "report.json", tmp / "report.md", {a, b});
  auto j = nlohmann::json::parse(read_file_text(tmp / "report.json"));
  ASSERT_EQ(j["reports"].size(), 2u);
  const auto& r = j["reports"][0];
  EXPECT_EQ(r["protocol"], "lerf-ovs");
  EXPECT_NEAR(r["summary"]["mIoU"].get<double>(), 0.45, 1e-12);
  EXPECT_EQ(r["summary"]["count"], 4);
  EXPECT_EQ(r["frames"].size(), 2u);
  EXPECT_EQ(r["queries"].size(), 3u);
  ASSERT_EQ(r["records"].size(), 4u);
  EXPECT_TRUE(r["records"][3]["biou"].is_null());
  EXPECT_FALSE(r["records"][3].contains("loc_hit"));
  EXPECT_EQ(r["records"][0]["loc_hit"], true);
  EXPECT_NEAR(r["summary"]["mean_seconds"].get<double>(), 0.015, 1e-12);
  EXPECT_EQ(r["records"][0]["seconds"], 0.01);
  EXPECT_FALSE(r["records"][2].contains("seconds"));
  EXPECT_FALSE(j["reports"][1]["summary"].contains("mean_seconds"));
  EXPECT_EQ(j["reports"][1]["mode"], "object");
  EXPECT_EQ(j["reports"][1]["extra"]["threshold"], 0.4);
  const std::string md = read_file_text(tmp / "report.md");
  // LERF-OVS: mAcc is the localisation accuracy (as LERF and LangSplat report it), pixel accuracy named apart.
  EXPECT_NEAR(r["summary"]["mAcc"].get<double>(), 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(r["summary"]["pixel_acc"].get<double>(), 0.85, 1e-12);
  EXPECT_NEAR(r["summary"]["loc_acc"].get<double>(), 2.0 / 3.0, 1e-12);
  EXPECT_NE(md.find("| lerf-ovs | toy | pixel | - | 4 | 66.67 | 45.00 | 33.33 | 85.00 | 66.67 | 15.0 |"),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("| lerf-ovs | toy | object |"), std::string::npos);
  EXPECT_NE(md.find("| mug | 2 | 85.00 | 25.00 | 12.50 | 100.00 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| f2 | cup \\| big | 70.00 | 30.00 | - | - |"), std::string::npos) << md;
  EXPECT_NE(md.find("| **scene mean** | 4 |"), std::string::npos);
  // Unwritable destination (a parent is a file): error, and no partial files left behind.
  atomic_write_text(tmp / "file", "x");
  EXPECT_THROW(write_reports(tmp / "r2.json", tmp / "file/r2.md", {a}), hgs::Error);
  EXPECT_FALSE(fs::exists(tmp / "r2.json"));
}

TEST(EvalReport, ProtocolGlue) {
  // 3D-OVS: one record per class, the image accuracy as the frame accuracy.
  OvsImageResult o;
  o.iou = {0.5, 0.0};
  o.biou = {0.25, 0.0};
  o.accuracy = 0.8;
  EvalReport r;
  add_3dovs_image(r, "v0", {"a", "b"}, o);
  o.iou = {1.0, 0.5};
  o.biou = {1.0, 0.5};
  o.accuracy = 0.6;
  add_3dovs_image(r, "v8", {"a", "b"}, o);
  ASSERT_EQ(r.records.size(), 4u);
  EXPECT_TRUE(std::isnan(r.records[0].acc));
  MeanRow s = scene_mean(r);
  EXPECT_DOUBLE_EQ(s.miou, 0.5);  // mean of image mIoUs 0.25 and 0.75
  EXPECT_DOUBLE_EQ(s.mbiou, (0.25 + 1.0 + 0.5) / 4);
  EXPECT_DOUBLE_EQ(s.macc, 0.7);
  EXPECT_THROW(add_3dovs_image(r, "v9", {"a"}, o), hgs::Error);
  // LERF: scores and localisation copied over.
  LerfQueryResult q;
  q.scores = {0.5, 0.25, 0.9};
  q.loc.hit = true;
  QueryRecord rec = lerf_record("f", "mug", q, 0.003);
  EXPECT_EQ(rec.iou, 0.5);
  EXPECT_EQ(rec.biou, 0.25);
  EXPECT_EQ(rec.acc, 0.9);
  EXPECT_EQ(rec.loc, 1);
  EXPECT_EQ(rec.seconds, 0.003);
}

TEST(EvalVisualize, TurboTable) {
  const Rgb c0 = turbo(0.f), c1 = turbo(1.f), mid = turbo(0.5f), q = turbo(1.f / 32.f);
  EXPECT_FLOAT_EQ(c0[0], 0.1357f);
  EXPECT_FLOAT_EQ(c1[0], 0.5659f);
  EXPECT_FLOAT_EQ(mid[1], 0.9819f);
  EXPECT_FLOAT_EQ(q[2], 0.5f * (0.1067f + 0.6857f));  // halfway between the first two samples
  EXPECT_EQ(turbo(-3.f), c0);
  EXPECT_EQ(turbo(7.f), c1);
  EXPECT_EQ(turbo(std::nanf("")), c0);
  // Low values are blue-dominant, high values red-dominant.
  EXPECT_GT(turbo(0.15f)[2], turbo(0.15f)[0]);
  EXPECT_GT(turbo(0.85f)[0], turbo(0.85f)[2]);
}

TEST(EvalVisualize, HeatmapAndOverlayPngs) {
  hgs::test::TempDir tmp;
  std::vector<float> v = {0.f, 1.f, 2.f, 4.f, 4.f, 4.f};
  save_heatmap_png(tmp / "h.png", v, 3, 2);
  Image h = load_image(tmp / "h.png", 3);
  ASSERT_EQ(h.width, 3);
  ASSERT_EQ(h.height, 2);
  for (int i = 0; i < 6; ++i) {
    const Rgb c = turbo(v[i] / 4.f);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(h.px[i * 3 + k], c[k], 0.6 / 255) << i;
  }
  // Fixed range.
  Image h2 = heatmap(v, 3, 2, 0.f, 8.f);
  EXPECT_FLOAT_EQ(h2.px[3 * 3 + 1], turbo(0.5f)[1]);
  EXPECT_THROW(heatmap(v, 4, 2), hgs::Error);

  // Overlay on a 5x5 grey image: pred tinted red at 50%, gt contour (inner boundary, not along the border) green.
  Image img(5, 5, 3, 0.2f);
  Mask pred = hgs::eval::test::ascii({".....", ".....", "..##.", "..##.", "....."});
  Mask gt = hgs::eval::test::ascii({"###..", "###..", "###..", ".....", "....."});
  Image o = overlay(img, pred, gt);
  auto px = [&](int x, int y, int k) { return o.px[(size_t(y) * 5 + x) * 3 + k]; };
  EXPECT_FLOAT_EQ(px(3, 3, 0), 0.6f);  // 0.5 * 0.2 + 0.5 * 1
  EXPECT_FLOAT_EQ(px(3, 3, 1), 0.1f);
  EXPECT_FLOAT_EQ(px(4, 4, 0), 0.2f);  // untouched
  EXPECT_FLOAT_EQ(px(2, 2, 1), 1.f);   // gt corner: contour drawn over the tint
  EXPECT_FLOAT_EQ(px(2, 2, 0), 0.f);
  EXPECT_FLOAT_EQ(px(2, 0, 1), 1.f);   // right side of gt
  EXPECT_FLOAT_EQ(px(0, 0, 1), 0.2f);  // along the image border: no contour
  EXPECT_FLOAT_EQ(px(1, 1, 1), 0.2f);  // gt interior
  save_overlay_png(tmp / "o.png", img, pred, gt);
  Image back = load_image(tmp / "o.png", 3);
  EXPECT_NEAR(back.at(3, 3, 0), 0.6f, 0.6 / 255);
  // Grey input and no ground truth.
  Image grey(5, 5, 1, 0.4f);
  Image og = overlay(grey, pred, {});
  EXPECT_FLOAT_EQ(og.at(0, 0, 2), 0.4f);
  EXPECT_FLOAT_EQ(og.at(2, 2, 0), 0.7f);
  EXPECT_THROW(overlay(img, Mask(3, 0), {}), hgs::Error);
  save_mask_png(tmp / "m.png", pred, 5, 5);
  LabelMap lm = load_label_png(tmp / "m.png");
  EXPECT_EQ(lm.at(3, 2), 255);
  EXPECT_EQ(lm.at(0, 0), 0);
}

TEST(EvalVisualize, ClassColoursAndOverlay) {
  // The first 20 class colours are pairwise distinct (RGB distance > 0.1) and in [0, 1].
  for (int a = 0; a < 20; ++a) {
    const Rgb ca = class_color(a);
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(ca[k], 0.f);
      EXPECT_LE(ca[k], 1.f);
    }
    for (int b = 0; b < a; ++b) {
      const Rgb cb = class_color(b);
      const float d = std::sqrt((ca[0] - cb[0]) * (ca[0] - cb[0]) + (ca[1] - cb[1]) * (ca[1] - cb[1]) +
                                (ca[2] - cb[2]) * (ca[2] - cb[2]));
      EXPECT_GT(d, 0.1f) << a << " vs " << b;
    }
  }
  // Class 0: hue 0 -> (v, v(1-s), v(1-s)) = (0.95, 0.2375, 0.2375).
  EXPECT_NEAR(class_color(0)[0], 0.95f, 1e-6);
  EXPECT_NEAR(class_color(0)[1], 0.2375f, 1e-6);
  Image img(2, 1, 3, 0.2f);
  Image o = class_overlay(img, {0, 3}, 0.5f);
  EXPECT_NEAR(o.px[0], 0.5f * 0.2f + 0.5f * 0.95f, 1e-6);
  EXPECT_NEAR(o.px[3 + 2], 0.5f * 0.2f + 0.5f * class_color(3)[2], 1e-6);
  EXPECT_THROW(class_overlay(img, {0}, 0.5f), hgs::Error);
}
