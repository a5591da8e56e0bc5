// Visualisations for queries and evaluation: an overlay of a predicted mask (tinted) and the ground-truth
// contour on the image, and colour-mapped relevancy heatmaps.
//
// Colour map: "turbo" (Google's rainbow map, 2019), stored as 17 RGB samples at t = 0, 1/16, ..., 1, taken
// from the published degree-5 polynomial approximation of turbo and clamped to [0, 1]; colours between
// samples are linearly interpolated. t runs dark blue (0) -> cyan -> green -> yellow -> red -> dark red (1).
#pragma once
#include <array>
#include <filesystem>
#include <vector>

#include "core/image.h"
#include "eval/metrics.h"

namespace hgs::eval {

using Rgb = std::array<float, 3>;

// Turbo colour of t (clamped to [0, 1]; NaN maps to 0).
Rgb turbo(float t);

// Colour-maps v [H, W]: t = (v - lo) / (hi - lo) clamped; lo >= hi means the map's own min and max
// (a constant map is drawn at t = 0). Returns an RGB image [H, W, 3].
Image heatmap(const std::vector<float>& v, int width, int height, float lo = 0.f, float hi = 0.f);
void save_heatmap_png(const std::filesystem::path& path, const std::vector<float>& v, int width, int height,
                      float lo = 0.f, float hi = 0.f);

struct OverlayStyle {
  Rgb tint{1.f, 0.f, 0.f};     // predicted mask colour (red)
  float alpha = 0.5f;          // tint opacity
  Rgb contour{0.f, 1.f, 0.f};  // ground-truth contour colour (green)
  int thickness = 1;           // contour width in pixels (inner boundary of the ground truth)
};

// The image (1 or 3 channels, drawn in colour) with `pred` tinted and the inner contour of `gt` drawn (pass an
// empty gt to skip it; contours are not drawn along the image border). Returns RGB [H, W, 3].
Image overlay(const Image& img, const Mask& pred, const Mask& gt, const OverlayStyle& style = {});
void save_overlay_png(const std::filesystem::path& path, const Image& img, const Mask& pred, const Mask& gt,
                      const OverlayStyle& style = {});

// Colour of class c for segmentation maps: hue c * 0.618034 turns (golden-ratio steps, so neighbouring ids
// differ strongly), saturation 0.75, value 0.95 alternating with 0.7 for odd c.
Rgb class_color(int c);
// The image (1/3/4 channels) blended with the colour of each pixel's class: out = (1 - alpha) img + alpha color.
// classes: [H, W] class index per pixel (e.g. the 3D-OVS argmax). Returns RGB [H, W, 3].
Image class_overlay(const Image& img, const std::vector<uint16_t>& classes, float alpha = 0.5f);

// A binary mask as a grey PNG (255 = inside).
void save_mask_png(const std::filesystem::path& path, const Mask& m, int width, int height);

}  // namespace hgs::eval
