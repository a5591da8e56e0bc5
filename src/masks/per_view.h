// Steps of `hgs masks associate` (associate.h): which keypoints of a label map are core points (away from every
// mask edge), which per-view masks fold into their whole (SAM's whole + parts), and how widely an object's 3D
// points spread (surfaces).
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <vector>

#include "core/image.h"
#include "masks/flatten.h"

namespace hgs::masks {

// [H, W] 1 where every pixel within chessboard distance `r` (clipped to the image: the frame is no edge) has the
// pixel's label. Separable min / max filters over the labels: O(H W r).
std::vector<uint8_t> core_pixels(const LabelMap& m, int r);

struct MaskInfo {      // one id of import.json
  double area = 0;     // the mask's own pixels
  double visible = 0;  // pixels it kept after flattening
  int part_of = 0;     // id of the whole it is a part of, 0 = none
};

// Per view: id -> root id, following part_of while the whole is tiled by its parts (it kept less than half of
// its pixels after flattening, or the areas of the masks that are part of it add up to at least half of its own)
// and covers at most `max_area` of the `image_px` pixels. A large mask holding a few small objects (a table with
// things on it) keeps them apart.
std::map<int, int> part_roots(const std::map<int, MaskInfo>& info, double image_px, double max_area);

// SAM's whole outlines its object: with `root` from part_roots (mask i has id i + 1; ids absent from `root` are
// their own root), every mask folded into another keeps only its pixels inside its root's own mask, and the view
// is flattened again (flatten_masks). A part and its whole carry independent boundary errors, so their union is
// biased outwards; the whole alone is not. A part whose whole is missing from the view is not folded and stays as
// it is. Returns false, leaving `out` alone, when no mask of the view is folded into another.
bool clip_parts_to_wholes(const std::vector<SourceMask>& masks, const std::map<int, int>& root, int width, int height,
                          Flattened& out);

// [H, W] 1 on every edge of a label map: a pixel with a 4-neighbour of another label (background included).
std::vector<uint8_t> label_edges(const LabelMap& m);
// [H, W] chessboard (L-infinity) distance from every pixel to the nearest pixel with src != 0 (w + h where there
// is none); two raster passes.
std::vector<int> chessboard_distance(const std::vector<uint8_t>& src, int w, int h);

// Per-pixel confidence for masks whose files give one score per mask (SAM's JSON and PNG folders): the score
// times a ramp from 1/2 on an edge (a pixel with a 4-neighbour of another label, background included) to 1 at
// `ramp` pixels (chessboard distance) from the nearest edge, as a mask logit's sigmoid crosses 1/2 on the object's
// outline. This is a prior, not a measurement: with Observation Fusion's tau1 = 1/2 it makes the edge pixels,
// where independent masks of one object disagree, no observation. `conf` [H, W] is scaled in place (empty: scores
// of 1 are assumed and it is filled).
void edge_ramp_confidence(const LabelMap& labels, int ramp, std::vector<float>& conf);

// Spread of a point set: the 80th percentile of the distances from the coordinate-wise median (0 when empty).
double robust_spread(const std::vector<Eigen::Vector3d>& points);

}  // namespace hgs::masks
