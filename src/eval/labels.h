// Ground-truth label loaders for the two open-vocabulary benchmarks (docs/formats.md):
//  - LERF-OVS: SCENE/label/frame_XXXXX.json, labelme-like polygons per object, rasterised with the even-odd
//    rule at pixel centres (x + 0.5, y + 0.5), vertices in pixel-corner units; objects sharing a category are
//    OR-ed into one mask; each category keeps its bounding boxes for the localisation metric. Also accepted:
//    "bbox": [[x1, y1], [x2, y2]] and "segmentation" as a list of polygons (each filled, then OR-ed).
//  - 3D-OVS: SCENE/segmentations/classes.txt (one class per line; used sorted) and
//    SCENE/segmentations/<view_index>/<class>.png (255 = inside) where <view_index> is the index of the view
//    in the name-sorted view list (folder names may be zero-padded, "03" = 3).
// Every malformed input raises a one-line hgs::Error naming the file and the problem.
#pragma once
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "eval/metrics.h"

namespace hgs::eval {

using Point2 = std::array<double, 2>;  // (x, y) in pixels, as in the label file (integer x = column index)

// Fill of a closed polygon (last vertex joins the first) exactly as cv2.fillPoly(mask, [np.int32(points)], 1),
// LangSplat's polygon_to_mask: vertices truncated to integers, the outline's pixels included, even-odd rule
// inside (labels.cpp says how, rule by rule). Parts outside the image are clipped. With one or two vertices
// only the outline is drawn (a point, a line), as OpenCV does.
Mask rasterize_polygon(const std::vector<Point2>& poly, int width, int height);  // -> [H, W] 0/1
// ORs the polygon into `mask` ([H, W]).
void fill_polygon(const std::vector<Point2>& poly, int width, int height, Mask& mask);

struct BBox {
  double x1 = 0, y1 = 0, x2 = 0, y2 = 0;  // pixels, x1 <= x2, y1 <= y2 (swapped on load if needed)
  // True when the integer pixel index (x, y) lies in the closed box [x1, x2] x [y1, y2] (LangSplat's test).
  bool contains_pixel(int x, int y) const;
};

struct LerfCategory {
  std::string name;
  Mask mask;                                  // [H, W] 0/1: OR of every polygon of the category
  std::vector<BBox> bboxes;                   // one per object entry, in file order
  std::vector<std::vector<Point2>> polygons;  // the polygons (downscaled if asked), in file order
};

struct LerfFrameLabels {
  std::filesystem::path file;
  std::string image_name;  // info.name, e.g. "frame_00009.jpg"
  std::string stem;        // file name without ".json", e.g. "frame_00009"
  int width = 0, height = 0;
  std::vector<LerfCategory> categories;  // in order of first appearance in the file
  // The category with this exact name, or nullptr.
  const LerfCategory* find(const std::string& name) const;
};

// Loads one label file. downscale F >= 1: labels for images downscaled by F (docs/formats.md): size
// floor(W/F) x floor(H/F), polygon vertices and boxes divided by F before rasterising. expect_width/height > 0:
// the (downscaled) label size must match (the image being evaluated).
LerfFrameLabels load_lerf_frame(const std::filesystem::path& json_file, int expect_width = 0, int expect_height = 0,
                                int downscale = 1);
// Loads every SCENE/label/*.json, sorted by file name. Fails if the folder is missing or holds no .json file.
std::vector<LerfFrameLabels> load_lerf_labels(const std::filesystem::path& scene, int expect_width = 0,
                                              int expect_height = 0, int downscale = 1);

// 3D-OVS label set of a scene: the sorted class list and the labelled views.
struct OvsLabelSet {
  std::filesystem::path dir;         // SCENE/segmentations
  std::vector<std::string> classes;  // sorted, unique, whitespace-trimmed, blank lines skipped
  struct View {
    int index;                  // index in the name-sorted view list
    std::filesystem::path dir;  // SCENE/segmentations/<folder>
  };
  std::vector<View> views;  // sorted by index
};
OvsLabelSet open_3dovs_labels(const std::filesystem::path& scene);

struct OvsViewLabels {
  int index = 0;  // view index
  int width = 0, height = 0;
  std::vector<Mask> masks;  // [C] masks [H, W] 0/1, in the order of OvsLabelSet::classes
};
// Loads the class masks of labels.views[i]. A pixel is inside iff its grey value is 255 (colour PNGs are
// converted to grey first). Every class PNG must exist and all must have one size. downscale F >= 1: each
// mask becomes floor(W/F) x floor(H/F), taking the centre pixel (F/2, F/2) of every F x F block, like
// hgs::downscale_labels. expect_* > 0: the (downscaled) size must be that.
OvsViewLabels load_3dovs_view(const OvsLabelSet& labels, size_t i, int expect_width = 0, int expect_height = 0,
                              int downscale = 1);

}  // namespace hgs::eval
