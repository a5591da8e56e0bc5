// Polygon rasterisation (cv2.fillPoly's rules: integer vertices, outline included, even-odd; border clipping) and the
// LERF-OVS / 3D-OVS label loaders with valid and malformed files.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "eval/labels.h"
#include "eval_test_util.h"
#include "test_util.h"

using namespace hgs;
using namespace hgs::eval;
using hgs::eval::test::ascii;
namespace fs = std::filesystem;

// Expected masks below are worked out by hand from cv2.fillPoly's rules (labels.cpp): vertices truncated to
// integers, the outline's 8-connected lines included, spans filled from ceil(left) to floor(right).
TEST(EvalPolygon, IntegerVerticesAndOutlineIncludedAsOpenCV) {
  // The square with corners (1, 1) and (3, 3) covers pixels 1..3 x 1..3: both ends included.
  EXPECT_EQ(rasterize_polygon({{1, 1}, {3, 1}, {3, 3}, {1, 3}}, 5, 5),
            ascii({".....", ".###.", ".###.", ".###.", "....."}));
  // Triangle (0,0), (4,0), (0,4): rows 0..3 fill 0 .. 4 - y; row 4 is the outline's vertex (0, 4).
  EXPECT_EQ(rasterize_polygon({{0, 0}, {4, 0}, {0, 4}}, 5, 5), ascii({"#####", "####.", "###..", "##...", "#...."}));
  // Orientation does not matter.
  EXPECT_EQ(rasterize_polygon({{1, 3}, {3, 3}, {3, 1}, {1, 1}}, 5, 5),
            ascii({".....", ".###.", ".###.", ".###.", "....."}));
}

TEST(EvalPolygon, FractionalVerticesTruncateTowardZero) {
  // numpy's float -> int32 cast: 0.9 -> 0, 2.9 -> 2, -0.7 -> 0 (not -1).
  EXPECT_EQ(rasterize_polygon({{0.9, 0.9}, {2.9, 0.9}, {2.9, 2.9}, {0.9, 2.9}}, 4, 4),
            ascii({"###.", "###.", "###.", "...."}));
  EXPECT_EQ(rasterize_polygon({{-0.7, 1}, {1.99, 1}, {1.99, 2}, {-0.7, 2}}, 3, 3), ascii({"...", "##.", "##."}));
}

TEST(EvalPolygon, BowTieEvenOdd) {
  // Edges (0,0)-(4,4), (4,4)-(4,0), (4,0)-(0,4), (0,4)-(0,0): row y crosses at 0, y, 4 - y, 4; pairs fill
  // [0, min] and [max, 4]; row 2 meets in the middle; row 4 is outline only.
  EXPECT_EQ(rasterize_polygon({{0, 0}, {4, 4}, {4, 0}, {0, 4}}, 5, 5),
            ascii({"#...#", "##.##", "#####", "##.##", "#...#"}));
}

TEST(EvalPolygon, ShallowEdgeFollowsOpenCVsLine) {
  // The outline from (0, 0) to (4, 1) is OpenCV's 8-connected line: (0,0) (1,0) (2,0) (3,1) (4,1); the fill of
  // the thin triangle (0,0), (4,1), (0,1) adds row 0's span [0, 0] only (row 1 is the bottom: outline).
  EXPECT_EQ(rasterize_polygon({{0, 0}, {4, 1}, {0, 1}}, 5, 2), ascii({"###..", "#####"}));
}

TEST(EvalPolygon, BorderAndOutsideAreClipped) {
  // Rows 0 (fill) and 1 (the bottom edge's outline) of a box that extends past the image.
  EXPECT_EQ(rasterize_polygon({{-10, -10}, {50, -10}, {50, 1}, {-10, 1}}, 5, 3), ascii({"#####", "#####", "....."}));
  EXPECT_EQ(rasterize_polygon({{3, -5}, {100, -5}, {100, 100}, {3, 100}}, 5, 3), ascii({"...##", "...##", "...##"}));
  EXPECT_EQ(rasterize_polygon({{10, 10}, {20, 10}, {20, 20}}, 5, 3), Mask(15, 0));
  EXPECT_EQ(rasterize_polygon({{0, 0}, {4, 0}}, 5, 3), ascii({"#####", ".....", "....."}));  // 2 vertices: a line
  EXPECT_EQ(rasterize_polygon({{1, 2}}, 5, 3), ascii({".....", ".....", ".#..."}));          // 1 vertex: a point
  EXPECT_EQ(rasterize_polygon({}, 5, 3), Mask(15, 0));
  EXPECT_EQ(rasterize_polygon({{-1e300, -1e300}, {1e300, -1e300}, {1e300, 1e300}, {-1e300, 1e300}}, 5, 3), Mask(15, 1));
}

TEST(EvalPolygon, SimplePolygonsCoverTheirClosedLatticePointsAndTheOutline) {
  // Random simple (star-shaped) polygons with integer vertices: every lattice point inside or on the boundary
  // is filled, and every other filled pixel is within one pixel of the boundary (an outline pixel).
  uint32_t s = 12345;
  auto rnd = [&](int n) {
    s = s * 1664525u + 1013904223u;
    return int((s >> 8) % uint32_t(n));
  };
  for (int trial = 0; trial < 40; ++trial) {
    const int n = 3 + trial % 8, W = 24, H = 18;
    std::vector<Point2> p;
    for (int k = 0; k < n; ++k) {
      const double a = 2 * 3.14159265358979 * (k + 0.1 + 0.8 * rnd(1000) / 1000.0) / n;
      const double r = 2 + rnd(9);
      p.push_back({std::floor(12 + r * std::cos(a)), std::floor(9 + r * std::sin(a))});
    }
    const Mask m = rasterize_polygon(p, W, H);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        bool in = false, on = false;
        double dist = 1e9;
        for (int i = 0, j = n - 1; i < n; j = i++) {
          const double xi = p[i][0], yi = p[i][1], xj = p[j][0], yj = p[j][1];
          const double ex = xj - xi, ey = yj - yi, len2 = ex * ex + ey * ey;
          const double t = len2 > 0 ? std::clamp(((x - xi) * ex + (y - yi) * ey) / len2, 0.0, 1.0) : 0.0;
          const double d = std::hypot(x - xi - t * ex, y - yi - t * ey);
          dist = std::min(dist, d);
          on |= d < 1e-9;
          if ((yi > y) != (yj > y) && x < ex * (y - yi) / ey + xi) in = !in;
        }
        if (in || on) {
          ASSERT_EQ(m[y * W + x], 1) << "trial " << trial << " pixel " << x << "," << y;
        } else if (m[y * W + x]) {
          ASSERT_LT(dist, 1.0) << "trial " << trial << " pixel " << x << "," << y;
        }
      }
  }
}

namespace {

void write(const fs::path& p, const std::string& s) {
  fs::create_directories(p.parent_path());
  atomic_write_text(p, s);
}

void expect_error(const std::function<void()>& f, const std::string& file, const std::string& what) {
  const std::string msg = hgs::test::error_of(f);
  EXPECT_NE(msg.find(file), std::string::npos) << msg;
  EXPECT_NE(msg.find(what), std::string::npos) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
}

const char* kValid = R"({"info": {"name": "frame_00001.jpg", "width": 6, "height": 4},
  "objects": [
    {"category": "mug", "bbox": [0, 0, 2, 2], "segmentation": [[0, 0], [2, 0], [2, 2], [0, 2]]},
    {"category": "plate", "bbox": [6, 4, 3, 1], "segmentation": [[3, 1], [6, 1], [6, 4], [3, 4]]},
    {"category": "mug", "bbox": [4.0, 0.0, 6.0, 1.0], "segmentation": [[4.0, 0.0], [6.0, 0.0], [6.0, 1.0], [4.0, 1.0]]}
  ]})";

}  // namespace

TEST(EvalLerfLabels, LoadsAndMergesCategories) {
  hgs::test::TempDir tmp;
  write(tmp / "scene/label/frame_00001.json", kValid);
  write(tmp / "scene/label/frame_00000.json",
        R"({"info": {"name": "frame_00000.jpg", "width": 6, "height": 4}, "objects": []})");
  write(tmp / "scene/label/notes.txt", "ignored");
  auto all = load_lerf_labels(tmp / "scene", 6, 4);
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[0].stem, "frame_00000");
  EXPECT_TRUE(all[0].categories.empty());
  const LerfFrameLabels& L = all[1];
  EXPECT_EQ(L.image_name, "frame_00001.jpg");
  EXPECT_EQ(L.width, 6);
  EXPECT_EQ(L.height, 4);
  ASSERT_EQ(L.categories.size(), 2u);
  EXPECT_EQ(L.categories[0].name, "mug");
  EXPECT_EQ(L.categories[1].name, "plate");
  const LerfCategory* mug = L.find("mug");
  ASSERT_NE(mug, nullptr);
  EXPECT_EQ(L.find("cup"), nullptr);
  // cv2.fillPoly includes the outline: the square (0,0)-(2,2) covers pixels 0..2; parts past the image are clipped.
  EXPECT_EQ(mug->mask, ascii({"###.##", "###.##", "###...", "......"}));
  EXPECT_EQ(L.find("plate")->mask, ascii({"......", "...###", "...###", "...###"}));
  ASSERT_EQ(mug->bboxes.size(), 2u);
  EXPECT_EQ(mug->polygons.size(), 2u);
  // Swapped corners are normalised; integer pixel indices inside the closed box count (LangSplat's test).
  const BBox& pb = L.find("plate")->bboxes[0];
  EXPECT_EQ(pb.x1, 3);
  EXPECT_EQ(pb.y1, 1);
  EXPECT_EQ(pb.x2, 6);
  EXPECT_EQ(pb.y2, 4);
  EXPECT_TRUE(pb.contains_pixel(3, 1));
  EXPECT_TRUE(pb.contains_pixel(5, 3));
  EXPECT_FALSE(pb.contains_pixel(2, 1));
  EXPECT_FALSE(pb.contains_pixel(3, 0));
  // Without an expected size any size is accepted.
  EXPECT_EQ(load_lerf_frame(tmp / "scene/label/frame_00001.json").width, 6);
}

TEST(EvalLerfLabels, NestedBoxAndSeveralPolygonsPerObject) {
  hgs::test::TempDir tmp;
  write(tmp / "f.json", R"({"info": {"name": "f.jpg", "width": 5, "height": 2},
    "objects": [{"category": "a", "bbox": [[4, 2], [0, 0]],
                 "segmentation": [[[0, 0], [1, 0], [1, 2], [0, 2]], [[3, 0], [5, 0], [5, 1], [3, 1]]]}]})");
  LerfFrameLabels L = load_lerf_frame(tmp / "f.json");
  ASSERT_EQ(L.categories.size(), 1u);
  EXPECT_EQ(L.categories[0].mask, ascii({"##.##", "##.##"}));
  EXPECT_EQ(L.categories[0].polygons.size(), 2u);
  ASSERT_EQ(L.categories[0].bboxes.size(), 1u);
  EXPECT_EQ(L.categories[0].bboxes[0].x1, 0.0);
  EXPECT_EQ(L.categories[0].bboxes[0].x2, 4.0);
  EXPECT_EQ(L.categories[0].bboxes[0].y2, 2.0);
}

TEST(EvalLerfLabels, Downscale) {
  hgs::test::TempDir tmp;
  write(tmp / "f.json", R"({"info": {"name": "f.jpg", "width": 9, "height": 8},
    "objects": [{"category": "a", "bbox": [2, 2, 6, 6], "segmentation": [[2, 2], [6, 2], [6, 6], [2, 6]]}]})");
  // F = 2: 4x4 labels, the square becomes (1,1)-(3,3) -> pixels 1..3 (outline included).
  LerfFrameLabels L = load_lerf_frame(tmp / "f.json", 4, 4, 2);
  EXPECT_EQ(L.width, 4);
  EXPECT_EQ(L.height, 4);
  EXPECT_EQ(L.categories[0].mask, ascii({"....", ".###", ".###", ".###"}));
  EXPECT_EQ(L.categories[0].bboxes[0].x2, 3.0);
  expect_error([&] { load_lerf_frame(tmp / "f.json", 9, 8, 2); }, (tmp / "f.json").string(),
               "label size 4x4 does not match the image size 9x8");
  expect_error([&] { load_lerf_frame(tmp / "f.json", 0, 0, 0); }, (tmp / "f.json").string(), "downscale factor");
  expect_error([&] { load_lerf_frame(tmp / "f.json", 0, 0, 10); }, (tmp / "f.json").string(),
               "smaller than the downscale");
}

TEST(EvalLerfLabels, MalformedFilesGiveClearErrors) {
  hgs::test::TempDir tmp;
  const fs::path f = tmp / "frame_00001.json";
  auto check = [&](const std::string& text, const std::string& what, int ew = 0, int eh = 0) {
    write(f, text);
    expect_error([&] { load_lerf_frame(f, ew, eh); }, f.string(), what);
  };
  check("{\"info\": ", "invalid JSON");
  check("[1, 2]", "expected a JSON object");
  check(R"({"objects": []})", "missing key \"info\"");
  check(R"({"info": {"name": "a", "width": 6, "height": 4}})", "missing key \"objects\"");
  check(R"({"info": {"width": 6, "height": 4}, "objects": []})", "info.name");
  check(R"({"info": {"name": "a", "height": 4}, "objects": []})", "missing key info.width");
  check(R"({"info": {"name": "a", "width": -6, "height": 4}, "objects": []})", "info.width must be a positive integer");
  check(R"({"info": {"name": "a", "width": 6, "height": 4}, "objects": []})",
        "label size 6x4 does not match the image size 8x4", 8, 4);
  const std::string head = R"({"info": {"name": "a", "width": 6, "height": 4}, "objects": [)";
  check(head + R"({"bbox": [0,0,1,1], "segmentation": [[0,0],[1,0],[1,1]]}]})", "objects[0]: missing key \"category\"");
  check(head + R"({"category": "mug", "segmentation": [[0,0],[1,0],[1,1]]}]})", "missing key \"bbox\"");
  check(head + R"({"category": "mug", "bbox": [0,0,1], "segmentation": [[0,0],[1,0],[1,1]]}]})", "bbox must be");
  check(head + R"({"category": "mug", "bbox": [[0,0],[1]], "segmentation": [[0,0],[1,0],[1,1]]}]})", "bbox must be");
  check(head + R"({"category": "mug", "bbox": [[0,0],[1,"a"]], "segmentation": [[0,0],[1,0],[1,1]]}]})",
        "objects[0].bbox[1][1] must be a number");
  check(head + R"({"category": "mug", "bbox": [0,0,1,1], "segmentation": [[[0,0],[1,0],[1,1]], [[0,0],[1,0]]]}]})",
        "polygon has 2 point(s), need at least 3");
  check(head + R"({"category": "mug", "bbox": [0,0,1,1], "segmentation": [[[0,0],[1,0],[1,1]], [[0,0],[1,0],[1]]]}]})",
        "objects[0].segmentation[1][2] must be an [x, y] pair");
  check(head + R"({"category": "mug", "bbox": [0,0,1,1]}]})", "missing key \"segmentation\"");
  check(head + R"({"category": "mug", "bbox": [0,0,1,1], "segmentation": [[0,0],[1,0]]}]})",
        "polygon has 2 point(s), need at least 3");
  check(head + R"({"category": "mug", "bbox": [0,0,1,1], "segmentation": [[0,0],[1,"x"],[1,1]]}]})",
        "objects[0].segmentation[1][1] must be a number");  // single polygon: segmentation[k] is point k
  check(head + R"({"category": "mug", "bbox": [0,0,1,1], "segmentation": [[0,0],[1],[1,1]]}]})",
        "objects[0].segmentation[1] must be an [x, y] pair");
  expect_error([&] { load_lerf_frame(tmp / "missing.json"); }, (tmp / "missing.json").string(), "");
  expect_error([&] { load_lerf_labels(tmp / "nothing"); }, (tmp / "nothing" / "label").string(),
               "no LERF-OVS label folder");
  fs::create_directories(tmp / "empty/label");
  expect_error([&] { load_lerf_labels(tmp / "empty"); }, (tmp / "empty" / "label").string(), "no LERF-OVS label files");
}

namespace {

void write_mask_png(const fs::path& p, const Mask& m, int w, int h, float on = 1.f) {
  fs::create_directories(p.parent_path());
  Image img(w, h, 1);
  for (size_t i = 0; i < m.size(); ++i) img.px[i] = m[i] ? on : 0.f;
  save_png(p, img);
}

}  // namespace

TEST(EvalOvsLabels, LoadsSortedClassesAndViews) {
  hgs::test::TempDir tmp;
  const fs::path seg = tmp / "scene/segmentations";
  write(seg / "classes.txt", "teddy bear\r\n  apple \n\nbook\n");
  const Mask apple = ascii({"##..", "....", "...."}), bear = ascii({"..##", "..##", "...."}),
             book = ascii({"....", "....", "####"});
  for (const char* v : {"03", "0"}) {
    write_mask_png(seg / v / "apple.png", apple, 4, 3);
    write_mask_png(seg / v / "teddy bear.png", bear, 4, 3);
    write_mask_png(seg / v / "book.png", book, 4, 3);
  }
  fs::create_directories(seg / "notes");  // not a view folder
  OvsLabelSet L = open_3dovs_labels(tmp / "scene");
  EXPECT_EQ(L.classes, (std::vector<std::string>{"apple", "book", "teddy bear"}));
  ASSERT_EQ(L.views.size(), 2u);
  EXPECT_EQ(L.views[0].index, 0);
  EXPECT_EQ(L.views[1].index, 3);
  OvsViewLabels V = load_3dovs_view(L, 1, 4, 3);
  EXPECT_EQ(V.index, 3);
  ASSERT_EQ(V.masks.size(), 3u);
  EXPECT_EQ(V.masks[0], apple);
  EXPECT_EQ(V.masks[1], book);
  EXPECT_EQ(V.masks[2], bear);
  // Grey 254 is not "inside" (only 255 is); colour PNGs are read through their grey value.
  write_mask_png(seg / "0" / "apple.png", apple, 4, 3, 254.f / 255.f);
  EXPECT_EQ(load_3dovs_view(L, 0).masks[0], Mask(12, 0));
  Image rgb(4, 3, 3, 0.f);
  for (int c = 0; c < 3; ++c) rgb.at(1, 1, c) = 1.f;
  save_png(seg / "0" / "apple.png", rgb);
  EXPECT_EQ(load_3dovs_view(L, 0).masks[0], ascii({"....", ".#..", "...."}));
  // Downscale by 2 takes the centre pixel (1, 1) of each 2x2 block: 2x1 masks.
  OvsViewLabels D = load_3dovs_view(L, 1, 2, 1, 2);
  EXPECT_EQ(D.width, 2);
  EXPECT_EQ(D.height, 1);
  EXPECT_EQ(D.masks[0], ascii({".."}));  // apple: row 1 is empty
  EXPECT_EQ(D.masks[2], ascii({".#"}));  // bear: (1,1) no, (3,1) yes
  EXPECT_THROW(load_3dovs_view(L, 1, 4, 3, 2), Error);
}

TEST(EvalOvsLabels, MalformedInputsGiveClearErrors) {
  hgs::test::TempDir tmp;
  const fs::path seg = tmp / "s/segmentations";
  expect_error([&] { open_3dovs_labels(tmp / "s"); }, seg.string(), "no 3D-OVS segmentation folder");
  fs::create_directories(seg);
  expect_error([&] { open_3dovs_labels(tmp / "s"); }, (seg / "classes.txt").string(), "file not found");
  write(seg / "classes.txt", "\n \n");
  expect_error([&] { open_3dovs_labels(tmp / "s"); }, (seg / "classes.txt").string(), "no class names");
  write(seg / "classes.txt", "a\nb\na\n");
  expect_error([&] { open_3dovs_labels(tmp / "s"); }, (seg / "classes.txt").string(), "line 3: duplicate class \"a\"");
  write(seg / "classes.txt", "a\nb\n");
  expect_error([&] { open_3dovs_labels(tmp / "s"); }, seg.string(), "no labelled views");
  write_mask_png(seg / "0" / "a.png", Mask(6, 1), 3, 2);
  fs::create_directories(seg / "00");
  expect_error([&] { open_3dovs_labels(tmp / "s"); }, seg.string(), "both name view 0");
  fs::remove_all(seg / "00");
  OvsLabelSet L = open_3dovs_labels(tmp / "s");
  expect_error([&] { load_3dovs_view(L, 0); }, (seg / "0" / "b.png").string(), "missing class mask for \"b\"");
  write_mask_png(seg / "0" / "b.png", Mask(8, 1), 4, 2);
  expect_error([&] { load_3dovs_view(L, 0); }, (seg / "0" / "b.png").string(),
               "mask size 4x2 does not match the view's other masks 3x2");
  write_mask_png(seg / "0" / "b.png", Mask(6, 1), 3, 2);
  EXPECT_EQ(load_3dovs_view(L, 0).masks.size(), 2u);
  expect_error([&] { load_3dovs_view(L, 0, 4, 2); }, (seg / "0" / "a.png").string(),
               "does not match the image size 4x2");
  write(seg / "0" / "b.png", "not a png");
  expect_error([&] { load_3dovs_view(L, 0); }, (seg / "0" / "b.png").string(), "cannot decode");
  expect_error([&] { load_3dovs_view(L, 5); }, seg.string(), "out of range");
}
