// Single-view hard association, the "without OF" ablation (as Segment-then-Splat initialises objects): each
// Gaussian takes the mask label at its projected centre in the first training view that sees it (with
// HybridConfig::occlusion_test, the first where the centre is not hidden behind the rendered surface:
// ObjectAssociation::refresh runs the occlusion test before either assignment); q is one-hot and fixed, and
// there are no view weights. Gaussians no view sees keep their previous q.
#pragma once
#include <cstdint>

#include "hybrid/fusion.h"

namespace hgs::hybrid {

// q [N, L] in/out.
void single_view_assignment(const ObservationTable& tab, int num_labels, float* q);

// Mask pooling of a reference feature map (eq. 9, reference side): for every label l present,
// z[l] = normalise(sum_p [labels(p) = l] S(p)); area[l] = pixel count. features [H, W, D], z [L, D], area [L].
void pool_reference(const float* features, const LabelMap& labels, int D, int num_labels, float* z, float* area);
// pool_reference of a feature grid [gh, gw, D] upsampled to the label map's size (scene.h's upsample_bilinear),
// one pixel at a time: the same bits, without the [H, W, D] map (1.8 GB for a 1258x707 view at D = 512).
void pool_reference_upsampled(const float* grid, int gh, int gw, const LabelMap& labels, int D, int num_labels,
                              float* z, float* area);

}  // namespace hgs::hybrid
