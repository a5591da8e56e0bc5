// HybridMethod: the full Hybrid Gaussians objective (paper eq. 15) as a train::Method plugged into the 3DGS
// trainer. Per step, for training view u:
//  prepare   Observation Fusion: q = softmax(s(w)/T) (association.h; the table is rebuilt every R iterations
//            and after densification, q is recomputed every step so the gradient reaches the view logits
//            exactly). From the renderer's SH colours c_n of the visible Gaussians (its preprocess phase), 4
//            channels per object present in u's mask, (q c, q) (object_channels.h), composited in the same
//            rasterization as the RGB image; for SCL the rasterizer also accumulates
//            a_{n,k} = sum_p M_k alpha T for every anchor object.
//  losses    terms "app" (eq. 6) and "bro" (eq. 14) per object (object_losses.h), "sem" (SCL, eqs. 9-10, or
//            the no-SCL cosine; semantic.h, which also takes f's Adam step). The trainer adds "rgb" (3DGS
//            photometric loss, weight lambda_rgb).
//  backward  object channels -> dq, and dc added to the renderer's colour gradient (its preprocess_backward
//            takes it through SH); dq -> view logits through the fusion and their Adam step.
//  update    f's Adam step for the no-SCL ablation.
//  after_step  refresh the observation table (every R iterations, after densification) or z = argmax q.
// Parameters registered in the trainer's optimiser: "lang" (f, per Gaussian, row-sparse, bfloat16 moments with
// half storage) and "view_logits" (array). Model extra groups: q, z, f (fields.h).
#pragma once
#include <vector>

#include "hybrid/association.h"
#include "hybrid/config.h"
#include "hybrid/data.h"
#include "hybrid/object_losses.h"
#include "hybrid/semantic.h"
#include "train/method.h"

namespace hgs::hybrid {

struct HybridLossValues {
  float app = 0, sem = 0, bro = 0;  // unweighted terms (bro with the scale rule's weights)
  int anchors = 0;
  // Wall time of the object-conditioned losses (+ BRO) and of the semantic pass (+ f's Adam step with SCL).
  double ms_app = 0, ms_sem = 0;
};

class HybridMethod final : public train::Method {
 public:
  HybridMethod(const HybridConfig& cfg, HybridData data, uint64_t seed);

  std::string name() const override { return "hybrid"; }
  void attach(GaussianModel& model, train::Adam& optim, const std::vector<train::TrainView>& views) override;
  float rgb_weight() const override { return cfg_.lambda_rgb; }
  void prepare(train::StepContext& c) override;
  void losses(train::StepContext& c) override;
  void backward(train::StepContext& c) override;
  void reduce(train::StepContext& c) override;
  void update(train::StepContext& c) override;
  void after_step(train::StepContext& c, bool densified) override;
  void release() override;
  nlohmann::json config() const override { return cfg_.to_json(); }
  std::vector<std::pair<std::string, std::vector<float>>> state() const override;
  void state_loaded(const std::string& where, const nlohmann::json& config, int n,
                    std::map<std::string, std::vector<float>>& arrays) override;

  const HybridConfig& hybrid_config() const { return cfg_; }
  const std::vector<float>& view_weights() const { return assoc_.weights(); }
  const std::vector<float>& view_logits() const { return assoc_.logits(); }
  const HybridLossValues& last_losses() const { return last_; }
  const ObjectAssociation& association() const { return assoc_; }

 private:
  HybridConfig cfg_;
  HybridData data_;
  uint64_t seed_;
  GaussianModel* model_ = nullptr;
  HybridFields fields_;
  ObjectAssociation assoc_;
  ObjectLosses object_losses_;
  SemanticPass semantic_;
  ObjectLayout layout_;
  std::vector<int> objects_;      // labels scored in this step: present in the view (all, or a sample)
  std::vector<float> channels_;   // [N, C] object channels (+ f for the no-SCL ablation)
  std::vector<float> d_channels_; // [H, W, C] dL/d the rendered channels
  std::vector<float> dq_;         // [N, L]
  std::vector<float> d_wsum_;     // [N, Jf]
  HybridLossValues last_;
};

}  // namespace hgs::hybrid
