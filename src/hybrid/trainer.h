// HybridTrainer: the full Hybrid Gaussians objective (paper eq. 15) on top of the 3DGS Trainer.
//
// Per iteration, for training view u:
//  1. Observation Fusion: q = softmax(s(w)/T) from the observation table and w = softmax(view logits)
//     (the table is rebuilt every R iterations and after densification; q is recomputed every step so the
//     gradient reaches the logits exactly).
//  2. Colours c_n by SH, then 4 channels per object present in the view's mask, (q c, q), composited in the
//     same rasterization as the RGB image; for SCL the rasterizer also accumulates a_{n,k} = sum_p M_k alpha T
//     for every foreground object (pixel-weighted sums).
//  3. Losses: lambda_rgb x 3DGS photometric loss on the image (see HybridConfig) + lambda_app x mean over objects
//     of (1 - lambda) L1 + lambda (1 - SSIM) of I_k against I * M_k (eq. 6) + lambda_bro x mean over objects of
//     eq. 14 (weighted by its band's share of the image, with a scale-invariant gradient: hybrid/bro.h) +
//     lambda_sem x mean over anchors of InfoNCE (eq. 10) on pooled predictions (eq. 9).
//  4. Backward: renderer gradients, then object channels -> dq, dc; SH backward for dc; SCL -> df, dq, da;
//     dq -> view logits through the fusion; Adam for everything (f_n row-sparse, rows formed on the fly, see
//     method_update).
// Ablations: without OF q is the single-view hard assignment (fixed); without SCL f_n is learned by a per-pixel
// cosine loss between the full semantic render sum f alpha T and the upsampled reference features.
// Model extra groups: "obj" [N, K+1] = q, "obj_id" [N, 1] = z, "lang" [N, D] = f.
#pragma once
#include <vector>

#include "hybrid/config.h"
#include "hybrid/data.h"
#include "hybrid/fusion.h"
#include "hybrid/object_channels.h"
#include "train/trainer.h"

namespace hgs::hybrid {

struct HybridLossValues {
  float rgb = 0, app = 0, sem = 0, bro = 0;  // bro: mean of eq. 14 over the objects, with the scale rule's weights
  int anchors = 0;
  // Wall time of the object-conditioned losses (+ BRO) and of the semantic pass (+ f's Adam step with SCL).
  double ms_app = 0, ms_sem = 0;
};

class HybridTrainer : public train::Trainer {
 public:
  HybridTrainer(const train::TrainConfig& cfg, const HybridConfig& hcfg, GaussianModel model,
                std::vector<train::TrainView> views, HybridData data, float extent);

  const HybridConfig& hybrid_config() const { return hc_; }
  const std::vector<float>& view_weights() const { return w_; }
  const std::vector<float>& view_logits() const { return logits_; }
  const HybridLossValues& last_losses() const { return last_; }
  // Rebuilds the observation table from the current centres and refreshes q and z.
  void refresh_observations();
  // Writes z = argmax q into "obj_id".
  void update_hard_ids();

 protected:
  void prepare_inputs(const train::TrainView& view, render::GaussianInputs& in, render::RenderSettings& rs) override;
  float extra_loss(const train::TrainView& view, const render::RenderOutputs& out, float* d_rgb,
                   render::OutputGrads& dout) override;
  void extra_param_grads(render::GaussianGrads& g) override;
  void method_update() override;
  void release_step_buffers() override;
  void after_step(train::StepInfo& info) override;
  std::vector<std::pair<std::string, std::vector<float>>> method_state() const override;
  nlohmann::json method_config() const override { return hc_.to_json(); }
  void method_state_loaded(const std::string& where, const nlohmann::json& config, int n,
                           std::map<std::string, std::vector<float>>& arrays) override;

 private:
  void fuse_now();
  float appearance_and_bro(const train::TrainView& view, const render::RenderOutputs& out);
  float semantic_contrastive(const render::RenderOutputs& out);
  float semantic_cosine(const render::RenderOutputs& out);

  HybridConfig hc_;
  HybridData data_;
  int L_ = 0, D_ = 0;
  ObservationTable obs_;
  std::vector<float> logits_, w_, lm_, lv_, dw_, dlogits_;  // [U]
  long view_steps_ = 0;
  std::vector<float> s_, dq_;                                // [N, L]
  std::vector<uint8_t> valid_;                               // [N]
  std::vector<float> colors_;                                // [N, 3]
  std::vector<float> extra_;                                 // [N, C]
  std::vector<float> d_extra_;                               // [H, W, C]
  std::vector<float> pixel_w_;                               // [H, W, Jf]
  std::vector<float> d_wsum_;                                // [N, Jf]
  struct ObjectScratch {  // per-thread buffers of the object-conditioned losses of one object
    explicit ObjectScratch(float lambda_dssim) : loss(lambda_dssim) {}
    train::PhotometricLoss loss;
    std::vector<float> gt;                 // [H, W, 3]
    std::vector<float> mask, band, morph;  // [H, W]
    std::vector<float> bgrad;              // [H, W, 3] BRO's gradient before its scale component is removed
  };
  std::vector<ObjectScratch> scratch_;                       // [threads]
  std::vector<float> obj_pred_, obj_grad_;                   // [J, H, W, 3] planar object renders / gradients
  std::vector<float> obj_opac_;                              // [J, H, W]
  std::vector<double> obj_app_, obj_bro_;                    // [J]
  std::vector<float> sref_;                                  // [H, W, D] (no-SCL ablation)
  std::vector<float> P_, dP_;                                // [Jf, D]
  std::vector<float> G_;                                     // [Jf, D] dP / (m + eps)
  std::vector<float> refs_;                                  // [R, D] InfoNCE candidates of one anchor
  std::vector<std::vector<int>> views_with_;                 // [L] training views whose SCL objects include l
  int view_ = 0, C_ = 0;
  ObjectLayout lay_;
  std::vector<int> objs_, fg_;
  float campos_[3] = {0, 0, 0};
  int active_degree_ = 0;
  HybridLossValues last_;
};

}  // namespace hgs::hybrid
