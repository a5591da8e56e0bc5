// Readers of the per-view mask files other tools write (docs/formats.md, "Importing masks"). Each checks its file
// against the view's image size (width x height of its COLMAP camera) and fails with a one-line error naming
// the file.
#pragma once
#include <filesystem>
#include <string>
#include <vector>

#include "core/image.h"
#include "masks/flatten.h"

namespace hgs::masks {

// SAM automatic mask generator JSON: a list of {segmentation: {size: [h, w], counts: string | [int]}, area, bbox,
// predicted_iou, stability_score, point_coords, crop_box}. Masks in list order.
std::vector<SourceMask> read_sam_json(const std::filesystem::path& file, int width, int height);
// segment-anything scripts/amg.py folder form: <i>.png binary masks + metadata.csv (id, area, bbox_x0, ...,
// predicted_iou, stability_score, ...). Masks in the order of the CSV's rows.
std::vector<SourceMask> read_sam_png_folder(const std::filesystem::path& folder, int width, int height);
// SAM2 (video predictor) label map: palette PNG (label = palette index) or 8/16-bit greyscale PNG (label = value).
LabelMap read_sam2_png(const std::filesystem::path& file, int width, int height);

// LangSplat preprocess.py output for one image. `<key>_s.npy`: [L, h, w] (L = 4 levels default, s, m, l; float32
// as LangSplat saves it, or any integer type), -1 = no mask, else an index into the concatenated mask list of all
// levels; `<key>_f.npy`: [M, D] float16/float32, one CLIP feature per mask.
struct LangSplatView {
  LabelMap labels;  // [height, width] (nearest resampling when h x w differs): index + 1, 0 = none
  int grid_h = 0, grid_w = 0, dim = 0;
  std::vector<float> grid;  // [grid_h, grid_w, D]: mean feature over the labelled pixels of each cell
  int num_masks = 0;        // M
};
// `stride`: cell size in pixels of the seg map for the feature grid (1 = one feature per pixel, exact).
LangSplatView read_langsplat(const std::filesystem::path& seg_file, const std::filesystem::path& feat_file, int level,
                             int width, int height, int stride);

// Minimal NPY reading of an integer-valued array of any common dtype (f2/f4/f8, i1/i2/i4/i8, u1/u2/u4) as int64.
std::vector<int64_t> read_npy_integers(const std::filesystem::path& file, std::vector<size_t>& shape);

}  // namespace hgs::masks
