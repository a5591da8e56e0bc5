// The adaptive batch rule (TrainConfig::batch_lr "adaptive"): Grendel's rule with a per-step gain measured from
// the batch's own gradients, so that a step of G views moves a parameter group about as far as G single-view steps
// would, whether its gradients are noise or signal.
//
// Why (Adam, one parameter, per-view gradients g_j with mean mu and variance s^2 over the views): G single-view
// steps drift by G lr mu / sqrt(mu^2 + s^2) (Adam divides by the root of its second moment, E[g^2]). One step of the
// batch mean gbar = sum_j g_j / G, whose second moment is E[gbar^2] = mu^2 + s^2 / G, drifts by
// lr_b mu / sqrt(mu^2 + s^2 / G). Equal drift needs
//   lr_b = G lr sqrt(E[gbar^2] / E[g^2]),
// which is lr sqrt(G) where the views' gradients are independent noise (s^2 >> G mu^2: Grendel's rule, derived
// there under that hypothesis) and lr G where they agree (s -> 0: early training, large Gaussians every view sees
// alike, where sqrt(G) moves G views' worth of images half as far at G = 4). The ratio is measured per 3DGS
// parameter group (means, scales, ...), as AdaScale (Johnson et al. 2020) measures its gain for SGD: per step, the
// batch mean's squared norm ||gbar||^2 and the views' mean squared norm sum_j ||g_j||^2 / G, each averaged with
// Adam's beta2 (of the batch, beta2^G), and
//   lr_mult = sqrt(G r),  r = avg ||gbar||^2 / avg (sum_j ||g_j||^2 / G)  in [1 / G, 1]  (Cauchy-Schwarz),
// on top of Grendel's sqrt(G) (Adam::lr_scale): the group's rate is lr sqrt(G) lr_mult, between lr sqrt(G) and
// lr G. One scalar per group per step crosses the ranks (the views' squared norms), not a second gradient.
// A per-group gain is an approximation of the per-parameter one above (a group's ratio is its parameters' ratios
// weighted by their second moments); the method's own parameters keep Grendel's rule.
#pragma once
#include <cstddef>

#include "train/adam.h"

namespace hgs::train {

// sum x_i^2 over n values, in double, in fixed chunks added in order: the same bits at any thread count.
// x: [n]
double squared_norm(const float* x, size_t n);

// One step of the rule for parameter p: batch_sq = ||gbar||^2 (the batch mean's gradient), view_sq = sum_j
// ||g_j||^2 / G (the views' mean), beta = Adam's beta2 of the batch. Updates p's averages and sets p.lr_mult (1 when
// nothing was measured yet). Returns p.lr_mult.
float adaptive_gain(AdamParam& p, double batch_sq, double view_sq, int G, double beta);

}  // namespace hgs::train
