// Hyper-parameters of the hybrid method (paper eq. 15 and sections 2.2-2.3). The paper gives no values; the
// defaults here are ours, chosen on the synthetic benchmark, and every one is a `hgs train` option.
#pragma once
#include <nlohmann/json.hpp>
#include <string>

namespace hgs::hybrid {

struct HybridConfig {
  bool use_of = true;   // Observation Fusion (else single-view hard assignment)
  bool use_scl = true;  // Semantic Contrastive Learning (else per-pixel cosine on the full semantic render)
  bool use_bro = true;  // Boundary Reconstruction Optimization (else lambda_bro = 0)
  // Plain 3DGS photometric loss on the full image (not in eq. 15; 0 = eq. 15 alone). On by default: eq. 15 alone
  // loses object mIoU on both presets at medium and high noise (figures: docs/ablation.md, "λ_rgb").
  float lambda_rgb = 1.0f;
  float lambda_app = 1.0f, lambda_sem = 0.1f, lambda_bro = 1.0f;
  float lambda_dssim = 0.2f;  // lambda of eq. 6
  float tau1 = 0.5f;          // mask confidence threshold (eq. 2)
  // Observation Fusion counts a pixel below tau1 as no observation (V_{n,u} = 0) instead of background
  // (fusion.h); false = eq. 2 as written (every unconfident pixel is background evidence). The masks of eqs. 6
  // and 14 keep M_{u,0} = 1 - OR_k M_{u,k} either way.
  bool unconfident_unobserved = true;
  // What an unlabelled mask pixel (no object id at all) tells Observation Fusion. "background": background
  // evidence, eq. 2's M_{u,0} = 1 - OR_k M_{u,k} as written. "unobserved": nothing, as an unconfident pixel (where
  // SAM + SAM2 segment everything, surfaces included, an unlabelled pixel is a gap: a track lost for a run of
  // views, an eroded edge; as background it outvotes the object's own views, docs/results.md section 10).
  // "auto" (the default, chosen on the development seeds, docs/results.md section 10): unobserved in a view whose
  // masks label at least 90 % of its pixels, background in the others (masks of objects only, as the paper's).
  // The masks of eqs. 6 and 14 keep M_{u,0} either way.
  std::string gaps = "auto";
  // Observation Fusion counts a view only where the Gaussian's centre is visible (not behind the surface the
  // current model renders there; fusion.h). On by default together with background_vote 0.5: alone it moves
  // some objects' Gaussians towards their label and others away, background_vote alone lets Gaussians hidden
  // behind an object take its label, and together they beat eq. 4 as written except at low noise (figures:
  // docs/results.md section 8). The single-view assignment of the no-OF rows uses it too (the first view where
  // the centre is visible), so that OF's row in Table 3 measures fusion alone; ablation tables made before
  // this change measured fusion and the occlusion test together. false = eq. 3's V (positive depth, in the image).
  bool occlusion_test = true;
  // T of eq. 5. s_{n,k} is a (weighted) fraction of views, so q_k / q_j = exp((s_k - s_j) / T): at T = 0.1 a label
  // that wins by 20 % of the views still leaves q_k ~ 0.88 and, under heavy mask noise, objects render below
  // the 0.5 mask threshold; 0.05 sharpens q (figures: docs/results.md section 3).
  float temperature = 0.05f;
  float fusion_eps = 1e-6f;  // epsilon of eq. 4
  // Weight of a background observation in eq. 4's numerator (fusion.h; 1 = the paper). M_{u,0} is the absence of
  // every mask, and under heavy mask noise missed and eroded small objects lose their own Gaussians to it; at 0.5
  // an object wins with more than a third of the views that see it. Alone (without the occlusion test) it helps
  // at high noise but lets Gaussians hidden behind an object take its label, so it is the default together with
  // the occlusion test (figures: docs/results.md section 8).
  float background_vote = 0.5f;
  float tau2 = 0.1f;  // InfoNCE temperature (eq. 10)
  // The background in SCL. Eq. 10 contrasts foreground objects only, so a view with fewer than two of them gives
  // an anchor no negative (its InfoNCE is 0 and passes no gradient) and, in a one-object scene, f is never trained
  // against anything: pixel-mode relevancy inside the object stays noise. "auto": a view whose SCL objects are
  // fewer than two adds its background (label 0, pooled like an object) as one more SCL class, an anchor and a
  // candidate; views with two or more keep eq. 10 exactly. "on": every view adds it (the background Gaussians'
  // f then learns the background's features, which the faithful LERF relevancy needs; docs/results.md).
  // "off": eq. 10 as written.
  std::string scl_background = "auto";
  // The semantic loss (eq. 10 through the pooled weights a_{n,k} = sum_p M_k alpha T) also moves opacities and
  // geometry. Off by default: SCL then trains f and (through q) the view weights only. With it, SCL lowers the
  // opacities of a high-noise scene's objects until objects fall below the mask threshold (figures:
  // docs/results.md section 3); true = the full gradient.
  bool sem_geometry = false;
  int fusion_every = 100;  // R: rebuild the observation table every R iterations (and after densification)
  int bro_kernel = 5;      // square structuring element of D and E (eq. 12)
  // BRO's gradient without the component that scales a whole object render (bro.h): eq. 14's own gradient
  // fades objects on noisy masks. false = eq. 14's plain gradient.
  bool bro_scale_invariant = true;
  // Scale rule of eq. 14 (bro.h): each object's term weighted by its band's share of the image, sum_d ||W^d||_1 /
  // (2 H W), so that BRO, like eq. 6, is a mean over the image and its weight against eq. 6 does not grow with
  // HW / |band| (smaller objects, higher resolution). false = eq. 14 as written (a mean over the band).
  bool bro_image_norm = true;
  float bro_eps = 1e-6f;
  int min_mask_pixels = 16;  // objects smaller than this in a view are not SCL anchors/candidates
  float lr_lang = 2.5e-3f;   // Adam learning rate of f_n
  // f_n stored in IEEE half and its Adam moments in bfloat16, both written with stochastic rounding (at 300k x 512:
  // 900 MB instead of 1.8 GB); false = float32 for all three.
  bool lang_half = true;
  float lr_view = 1e-2f;  // Adam learning rate of the view reliability logits
  float lang_init_std = 0.1f;
  // An approximation of eqs. 6 and 14 for speed (0 = off, the exact sums). Each step renders and scores only M
  // of the J objects present in the view, drawn uniformly without replacement from the view's random stream;
  // both terms are means over the objects scored (1/M instead of 1/J), so the step's loss and gradient are
  // unbiased estimates of the exact ones (every object is drawn with probability M/J and then weighs J/M times
  // more; the test ObjectSampling.* checks the expectation over all subsets). The object channels of the render
  // shrink from 4J to 4M. See docs/performance.md for the speed and the accuracy measured.
  int objects_per_step = 0;
  // How the object channels are composited; both exact (the same function up to float rounding). true: a base
  // render plus per-object sparse groups (object_groups.h), the cost of one or two objects per Gaussian visit;
  // false: 4 dense channels per object (object_channels.h).
  bool sparse_objects = true;

  nlohmann::json to_json() const;
  static HybridConfig from_json(const nlohmann::json& j);
};

}  // namespace hgs::hybrid
