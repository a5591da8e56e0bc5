// Fragments of one object: SAM2 leaves one physical object under several mask ids (a track lost and re-born
// under a new id, a part SAM cut off its whole), and Observation Fusion gives each of them Gaussians of their own,
// so an answer made of the best label alone covers only part of the object. The fragment rule (a rule of this
// project, not in the paper) adds to the best label every label that (a) answers the text nearly as well: its
// cosine is below the best's by at most `margin` times the best's lead over the median label (a relative margin:
// trained with SCL the labels' cosines spread over about 0.5, without it over a few hundredths), and (b) lies where
// the best label lies: the boxes of their Gaussians' centres (5th to 95th percentile per axis of the Gaussians
// whose hard id is the label and whose opacity is above 0.3), each grown by 20 % of its size per side, meet. A
// second instance of the same class elsewhere in the scene fails (b); a neighbour of another class fails (a).
// The best label here is the anchor (query.h: choose_objects), the best label with a valid box: OF can leave a
// track's first id without Gaussians (a majority of its views went to the re-born id), and its embedding, pooled
// from soft probabilities, can still rank first.
// Measured in docs/results.md, "Fragments of one object" and "Labels without Gaussians".
#pragma once
#include <vector>

#include "model/gaussian_model.h"

namespace hgs::query {

// The fragment rule's default margin, a fraction of the best label's cosine lead over the median label
// (docs/results.md, "Fragments of one object": chosen on the development seeds).
inline constexpr float kFragmentMargin = 0.2f;

struct LabelBox {
  float lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
  bool valid = false;  // at least 5 opaque Gaussians carry the label
};

// One box per label (hard ids z_n in 0..L-1): [L].
std::vector<LabelBox> label_boxes(const GaussianModel& m, int num_labels);

// Whether two boxes, each grown by 20 % of its extent per side, meet (false when either is invalid).
bool boxes_meet(const LabelBox& a, const LabelBox& b);

}  // namespace hgs::query
