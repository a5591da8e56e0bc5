// Per-view inputs of the hybrid method, loaded once before training: confidence-filtered masks, the objects
// present, their areas, and the mask-pooled reference language features (eq. 9, reference side).
#pragma once
#include <vector>

#include "hybrid/config.h"
#include "hybrid/fusion.h"
#include "scene/scene.h"

namespace hgs::hybrid {

struct HybridView {
  std::vector<int> present;  // labels present in the filtered mask (background 0 included when present)
  std::vector<int> fg;       // foreground labels with area >= min_mask_pixels
  std::vector<int> scl;      // SCL classes (anchors / candidates): fg, plus 0 under cfg.scl_background
  std::vector<float> area;   // [L] pixel count per label
  std::vector<float> zref;   // [L, D] unit pooled reference features (zero rows where absent)
  // Only for the no-SCL ablation: the raw patch-grid features, upsampled per step. [ph, pw, D]
  std::vector<float> patch_features;
  int ph = 0, pw = 0;
};

struct HybridData {
  int num_labels = 0;           // K + 1
  int dim = 0;                  // D
  std::vector<MaskView> masks;  // per training view: camera + filtered labels (Observation Fusion input)
  std::vector<HybridView> views;
};

// The SCL classes of a view from its foreground labels fg and its background area (config.h scl_background):
// fg, preceded by the background label 0 when the rule adds it and the background has >= min_pixels pixels.
std::vector<int> scl_classes(const std::vector<int>& fg, float background_area, const std::string& rule,
                             int min_pixels);

// A MaskView with v's image size, intrinsics and pose (no labels yet).
MaskView mask_view_geometry(const View& v);

// Loads masks (+ confidences, thresholded at tau1) and features of the given views. Fails with a clear
// message when masks or features are missing (the hybrid method needs both).
HybridData load_hybrid_data(const Scene& scene, const std::vector<int>& view_indices, const HybridConfig& cfg,
                            bool progress);

}  // namespace hgs::hybrid
