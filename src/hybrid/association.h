// ObjectAssociation: the training-time state of Observation Fusion (paper eqs. 2-5, kernels in fusion.h) for
// one model: the observation table, the view reliability logits (registered in the optimiser as the array
// parameter "view_logits" [U], so their Adam state and checkpointing are the shared ones), w = softmax(logits),
// the fused evidence s and which Gaussians have a valid view. Without OF (the ablation), q is the single-view
// hard assignment (assign.h) and there are no view weights to learn.
#pragma once
#include <cstdint>
#include <vector>

#include "hybrid/config.h"
#include "hybrid/fields.h"
#include "hybrid/fusion.h"
#include "render/rasterize.h"
#include "render/renderer.h"
#include "train/adam.h"
#include "train/reducer.h"

namespace hgs::hybrid {

// The occlusion test of Observation Fusion for every view (fusion.h, hide_occluded): the model's depth in each
// view (surface depth = expected depth / alpha where alpha > 0.5) at the pixels the test reads only (the
// observed Gaussians' centres, occlusion_pixels; render::RendererT::depth_at: the same bits as a whole render
// there), and the hidden Gaussians' entries of `table` marked as no observation. Costs one projection and binning
// per training view, and compositing at those pixels. near_plane: the training cameras' (a Gaussian nearer to the
// camera than it is culled in training, so it is no surface here either). `scratch`: the renderer and buffers a
// caller keeps between rebuilds (none: made for this call).
struct OcclusionScratch {
  render::GaussianRenderer renderer;
  render::TilePixels pixels;
  std::vector<uint8_t> chosen;      // [H, W] the pixels the test reads
  std::vector<float> alpha, depth;  // [M] at those pixels
  std::vector<float> surface;       // [H, W], written and read at those pixels only
  void release() {                  // frees every buffer (move-assigned empties: `= {}` would keep the capacity)
    renderer.release();
    pixels = render::TilePixels();
    chosen = std::vector<uint8_t>();
    alpha = std::vector<float>();
    depth = std::vector<float>();
    surface = std::vector<float>();
  }
};
void hide_occluded_all(const GaussianModel& m, const std::vector<MaskView>& views, float near_plane,
                       ObservationTable& table, OcclusionScratch* scratch = nullptr);

class ObjectAssociation {
 public:
  static constexpr const char* kLogits = "view_logits";

  ObjectAssociation(const HybridConfig& cfg, const std::vector<MaskView>* masks, int num_labels);
  // Registers the view logits in `optim` (eps 1e-8, torch's default: the 3DGS eps of 1e-15 is for its own
  // parameters' scales).
  void attach(train::Adam& optim);
  void set_config(const HybridConfig& cfg) { cfg_ = cfg; }
  // Rebuilds the observation table from the current centres, then q (fused or single-view) and z. near_plane:
  // the training cameras' (no observation nearer than it; the occlusion test's depth renders at it).
  void refresh(GaussianModel& m, HybridFields& h, float near_plane);
  // q = softmax(s(w) / T) from the current table and logits, and z = argmax q (OF only).
  void fuse(int n, HybridFields& h);
  // z = argmax q.
  void update_hard_ids(int n, HybridFields& h) const;
  // dq [N, L] of one view -> the view logits' gradient through eqs. 4-5 and the softmax over views, added to
  // the step's sum (first = the step's first view: overwrites). OF only.
  void backward(int n, const HybridFields& h, const float* dq, bool first);
  // The step's sum over the ranks (rank order), then the logits' Adam step with it x scale (1 / G).
  void reduce(train::Reducer& r);
  void update(train::Adam& optim, float scale);

  const std::vector<float>& weights() const;  // [U] softmax of the current logits
  const ObservationTable& table() const { return table_; }
  // Frees the depth renders' buffers (HybridMethod::release, before densification).
  void release() { occlusion_.release(); }
  // The last fuse()'s s [N, L] and valid [N] (null before the first, and without OF).
  const float* fused_s() const { return s_.empty() ? nullptr : s_.data(); }
  const uint8_t* fused_valid() const { return valid_.empty() ? nullptr : valid_.data(); }
  // The last fuse()'s base_association of each row of q [n] (null before the first, without OF, or for another n).
  const float* fused_base(int n) const { return n > 0 && base_.size() == size_t(n) ? base_.data() : nullptr; }
  // Restores a saved table (checked by the caller).
  void restore_table(int n, std::vector<uint16_t> labels);

 private:
  HybridConfig cfg_;
  const std::vector<MaskView>* masks_;
  int L_;
  ObservationTable table_;
  OcclusionScratch occlusion_;                               // the depth renders' buffers, kept between rebuilds
  std::vector<float> logits_, dw_, dlogits_, step_dlogits_;  // [U]
  bool step_set_ = false;
  mutable std::vector<float> w_;  // [U] softmax(logits_)
  std::vector<float> s_;          // [N, L]
  std::vector<uint8_t> valid_;    // [N]
  std::vector<float> den_;        // [N] eq. 4's normalisers of the last fuse() (its backward reads them)
  std::vector<float> base_;       // [N] the smallest of each row of q (the object channels' b_n)
};

}  // namespace hgs::hybrid
