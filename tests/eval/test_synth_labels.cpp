// The label loaders on a scene written by `hgs synth`: LERF-OVS polygons rasterise back to the exact
// ground-truth instance masks (hole-filled; exactly equal for objects without holes), and the 3D-OVS masks
// of objects equal the instance masks of the name-sorted view they index, with the background surfaces as
// classes of their own.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "eval/instances.h"
#include "eval/labels.h"
#include "synth/synth.h"
#include "synth_options.h"
#include "test_util.h"

using namespace hgs;
using namespace hgs::eval;
namespace fs = std::filesystem;

namespace {

// Fills the holes of a mask: outside pixels not 4-connected to the image exterior (the complement of an
// 8-connected foreground uses 4-connectivity).
Mask fill_holes(const Mask& m, int w, int h) {
  Mask reach(m.size(), 0);
  std::vector<int> stack;
  auto push = [&](int x, int y) {
    if (x < 0 || y < 0 || x >= w || y >= h) return;
    const size_t i = size_t(y) * w + x;
    if (m[i] || reach[i]) return;
    reach[i] = 1;
    stack.push_back(static_cast<int>(i));
  };
  for (int x = 0; x < w; ++x) {
    push(x, 0);
    push(x, h - 1);
  }
  for (int y = 0; y < h; ++y) {
    push(0, y);
    push(w - 1, y);
  }
  while (!stack.empty()) {
    const int i = stack.back();
    stack.pop_back();
    const int x = i % w, y = i / w;
    push(x - 1, y);
    push(x + 1, y);
    push(x, y - 1);
    push(x, y + 1);
  }
  Mask out(m.size());
  for (size_t i = 0; i < m.size(); ++i) out[i] = reach[i] ? 0 : 1;
  return out;
}

}  // namespace

TEST(EvalSynthLabels, PolygonsAndSegmentationsMatchInstanceMasks) {
  hgs::test::TempDir tmp;
  const synth::SynthOptions o = hgs::test::SmallSynth().points(500).feature_dim(16);
  const fs::path scene = tmp / "scene";
  synth::generate(scene, o);

  const std::map<int, std::string> names = load_object_names(scene);
  ASSERT_EQ(names.size(), 4u);
  std::vector<std::string> views;
  for (auto& e : fs::directory_iterator(scene / "images")) views.push_back(e.path().filename().string());
  std::sort(views.begin(), views.end());

  // LERF-OVS.
  auto frames = load_lerf_labels(scene, o.width, o.height);
  ASSERT_EQ(frames.size(), 2u);  // views 0 and 8 are held out
  int exact = 0, with_holes = 0, present = 0;
  for (auto& F : frames) {
    const InstanceLabels inst = load_instance_masks(scene, F.image_name, names, o.width, o.height);
    ASSERT_EQ(inst.ids.size(), 4u);
    for (size_t k = 0; k < inst.ids.size(); ++k) {
      const std::string& name = inst.names[k];
      EXPECT_EQ(name, names.at(inst.ids[k]));
      const Mask& gt = inst.masks[k];
      long n = 0;
      for (auto v : gt) n += v;
      const LerfCategory* c = F.find(name);
      if (n == 0) {
        EXPECT_EQ(c, nullptr) << F.stem << " " << name;
        continue;
      }
      ++present;
      ASSERT_NE(c, nullptr) << F.stem << " " << name;
      const Mask filled = fill_holes(gt, o.width, o.height);
      EXPECT_EQ(c->mask, filled) << F.stem << " " << name;
      if (filled == gt) {
        EXPECT_EQ(c->mask, gt);
        ++exact;
      } else {
        ++with_holes;
      }
      // Every bbox holds its polygon, and the category's pixels lie in the union of its boxes.
      for (size_t i = 0; i < gt.size(); ++i)
        if (c->mask[i]) {
          bool in = false;
          for (auto& b : c->bboxes) in |= b.contains_pixel(int(i % o.width), int(i / o.width));
          ASSERT_TRUE(in) << F.stem << " " << name;
        }
    }
  }
  EXPECT_GE(present, 4);
  EXPECT_GE(exact, present / 2) << "too few hole-free objects to test exact equality (" << with_holes << " with holes)";

  // 3D-OVS: the objects and the background surfaces (synth.json background_concepts that are no object) are
  // classes. Object classes equal the instance masks; surface classes are disjoint, lie on background pixels
  // and together label every background pixel but the sky's.
  OvsLabelSet L = open_3dovs_labels(scene);
  const auto meta = nlohmann::json::parse(read_file_text(scene / "synth.json"));
  std::vector<std::string> sorted, surfaces;
  for (auto& [id, name] : names) sorted.push_back(name);
  for (const auto& c : meta["background_concepts"]) {
    const std::string n = c.get<std::string>();
    if (std::find(sorted.begin(), sorted.end(), n) == sorted.end()) surfaces.push_back(n);
  }
  ASSERT_GE(surfaces.size(), 1u);
  sorted.insert(sorted.end(), surfaces.begin(), surfaces.end());
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(L.classes, sorted);
  ASSERT_EQ(L.views.size(), 2u);
  EXPECT_EQ(L.views[0].index, 0);
  EXPECT_EQ(L.views[1].index, 8);
  for (size_t v = 0; v < L.views.size(); ++v) {
    OvsViewLabels V = load_3dovs_view(L, v, o.width, o.height);
    const LabelMap inst = load_label_png(scene / "gt/instances" / views[V.index]);
    std::vector<int> covered(inst.v.size(), 0);
    for (size_t c = 0; c < L.classes.size(); ++c) {
      for (size_t i = 0; i < inst.v.size(); ++i) covered[i] += V.masks[c][i];
      int id = -1;
      for (auto& [k, name] : names)
        if (name == L.classes[c]) id = k;
      if (id < 0) continue;  // a surface class
      Mask gt(inst.v.size());
      for (size_t i = 0; i < gt.size(); ++i) gt[i] = inst.v[i] == id;
      EXPECT_EQ(V.masks[c], gt) << "view " << V.index << " class " << L.classes[c];
    }
    size_t background = 0, labelled_background = 0;
    for (size_t i = 0; i < inst.v.size(); ++i) {
      ASSERT_LE(covered[i], 1) << "classes overlap at pixel " << i;
      if (inst.v[i] == 0) background++, labelled_background += covered[i];
      else ASSERT_EQ(covered[i], 1);
    }
    EXPECT_GT(labelled_background, background / 2) << "view " << V.index << ": surfaces label too little";
    // Downscaled labels agree with the downscaled instance map.
    OvsViewLabels D = load_3dovs_view(L, v, o.width / 2, o.height / 2, 2);
    const InstanceLabels I2 = load_instance_masks(scene, views[V.index], names, o.width / 2, o.height / 2, 2);
    for (size_t c = 0; c < L.classes.size(); ++c)
      for (size_t k = 0; k < I2.names.size(); ++k)
        if (I2.names[k] == L.classes[c]) {
          EXPECT_EQ(D.masks[c], I2.masks[k]);
        }
  }
}

TEST(EvalInstances, MalformedObjectNamesAndMissingMaps) {
  hgs::test::TempDir tmp;
  const fs::path f = tmp / "s/masks/objects.json";
  fs::create_directories(f.parent_path());
  auto err = [&](const std::string& text) {
    atomic_write_text(f, text);
    try {
      load_object_names(tmp / "s");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_NE(err("{").find(f.string() + ": invalid JSON"), std::string::npos);
  EXPECT_NE(err("[]").find("expected an object"), std::string::npos);
  EXPECT_NE(err("{}").find("no objects"), std::string::npos);
  EXPECT_NE(err(R"({"x": "mug"})").find("key \"x\" is not an object id"), std::string::npos);
  EXPECT_NE(err(R"({"0": "mug"})").find("key \"0\" is not an object id"), std::string::npos);
  EXPECT_NE(err(R"({"1": 5})").find("name of object 1 must be a non-empty string"), std::string::npos);
  EXPECT_NE(err(R"({"1": "a", "01": "b"})").find("object id 1 appears twice"), std::string::npos);
  atomic_write_text(f, R"({"2": "mug", "1": "plate"})");
  auto names = load_object_names(tmp / "s");
  EXPECT_EQ(names.at(1), "plate");
  EXPECT_THROW(load_instance_masks(tmp / "s", "frame_00001.png", names), Error);
  LabelMap lm(3, 2, 0);
  lm.at(2, 1) = 2;
  save_label_png(tmp / "s/gt/instances/v.png", lm);
  InstanceLabels I = load_instance_masks(tmp / "s", "v.png", names);
  EXPECT_EQ(I.ids, (std::vector<int>{1, 2}));
  EXPECT_EQ(I.masks[0], Mask(6, 0));
  EXPECT_EQ(I.masks[1], (Mask{0, 0, 0, 0, 0, 1}));
  EXPECT_THROW(load_instance_masks(tmp / "s", "v.png", names, 4, 2), Error);
  // A JPEG view's map is gt/instances/<stem>.png (the image's own name is the fallback).
  InstanceLabels J = load_instance_masks(tmp / "s", "v.jpg", names);
  EXPECT_EQ(J.masks[1], I.masks[1]);
  std::string missing;
  try {
    load_instance_masks(tmp / "s", "w.jpg", names);
  } catch (const Error& e) {
    missing = e.what();
  }
  EXPECT_NE(missing.find("w.jpg: file not found"), std::string::npos) << missing;
  EXPECT_NE(missing.find("w.png was tried too"), std::string::npos) << missing;
}
