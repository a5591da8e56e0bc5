// HybridMethod: the full Hybrid Gaussians objective (paper eq. 15) as a train::Method plugged into the 3DGS
// trainer. Per view u of a step:
//  prepare   Observation Fusion: q = softmax(s(w)/T) (association.h; recomputed from the view logits once per
//            step, so the gradient reaches them exactly). From the renderer's SH colours c_n of the visible
//            Gaussians (its preprocess phase), 4 channels per object present in u's mask (or a sample of them,
//            --objects-per-step), (q_k c, q_k), composited in the same rasterization as the RGB image: as a
//            base render plus sparse per-object groups (object_groups.h; sparse_objects, the default) or as 4
//            dense channels per object (object_channels.h); for SCL the rasterizer also accumulates
//            a_{n,k} = sum_p M_k alpha T for every anchor object.
//  losses    terms "app" (eq. 6) and "bro" (eq. 14) per object (object_losses.h), "sem" (SCL, eqs. 9-10, or the
//            no-SCL cosine; semantic.h). The trainer adds "rgb" (3DGS photometric loss, weight lambda_rgb).
//  backward  object channels -> dq, and dc added to the renderer's colour gradient (its preprocess_backward takes
//            it through SH); dq -> the view logits' gradient through the fusion (eqs. 4-5), summed over the step.
// Once per step:
//  reduce      the view logits' gradients and f's factored gradients across ranks
//  update      the view logits' Adam step and f's row-sparse Adam step (semantic.h)
//  after_step  rebuild the observation table (every R images seen, after densification) or refresh z = argmax q.
// Parameters registered in the trainer's optimiser: "lang" (f, per Gaussian, row-sparse, bfloat16 moments with
// half storage) and "view_logits" (array). Model extra groups: q, z, f (fields.h), bound from the model each hook
// receives. stats(): the last view's unweighted terms ("app", "bro", "sem"), SCL anchors ("anchors"), the wall
// time of the object losses and the semantic pass ("ms_app", "ms_sem"), and the view weights w ("view_weights").
#pragma once
#include <vector>

#include "hybrid/association.h"
#include "hybrid/config.h"
#include "hybrid/data.h"
#include "hybrid/object_groups.h"
#include "hybrid/object_losses.h"
#include "hybrid/semantic.h"
#include "train/method.h"

namespace hgs::hybrid {

class HybridMethod final : public train::Method {
 public:
  HybridMethod(const HybridConfig& cfg, HybridData data, uint64_t seed);

  std::string name() const override { return "hybrid"; }
  void attach(GaussianModel& model, train::Adam& optim, const std::vector<train::TrainView>& views) override;
  float rgb_weight() const override { return cfg_.lambda_rgb; }
  void prepare(const train::ViewStep& v, const train::PrepareIO& io) override;
  void losses(const train::ViewStep& v, const train::LossIO& io) override;
  void backward(const train::ViewStep& v, const train::BackwardIO& io) override;
  void reduce(train::Reducer& reducer) override;
  void update(const train::UpdateIO& io) override;
  void after_step(const train::StepEnd& end) override;
  void release() override;
  train::MethodStats stats() const override;
  nlohmann::json config() const override { return cfg_.to_json(); }
  std::vector<std::pair<std::string, std::vector<float>>> state() const override;
  void state_loaded(const std::string& where, const nlohmann::json& config, int n,
                    std::map<std::string, std::vector<float>>& arrays) override;

 private:
  // The last view's loss values (unweighted) and the wall time of its two loss parts (stats()).
  struct LastLosses {
    float app = 0, sem = 0, bro = 0;
    int anchors = 0;
    double ms_app = 0, ms_sem = 0, ms_buffers = 0;  // ms_buffers: the channel buffers around the losses
    ObjectLosses::PhaseTimes app_phases;
  };
  void init_language(GaussianModel& model) const;
  float near_plane() const;  // the training cameras'

  HybridConfig cfg_;
  HybridData data_;
  uint64_t seed_;
  // The trainer's views (attach; the trainer owns this method, cannot be moved and sets a resumed run's near plane
  // on them in place): the observation table is built at their near plane.
  const std::vector<train::TrainView>* views_ = nullptr;
  ObjectAssociation assoc_;
  ObjectLosses object_losses_;
  SemanticPass semantic_;
  ObjectLayout layout_;
  std::vector<int> objects_;       // labels scored in this view: present in its mask (all, or a sample)
  std::vector<float> channels_;    // [N, C] object channels, or the base channels (+ f for the no-SCL ablation)
  ObjectGroups groups_;            // the sparse object groups (sparse_objects)
  std::vector<float> d_channels_;  // [H, W, C] dL/d the object layout's channels (dense path only)
  std::vector<float> d_dense_;     // [H, W, 4 + S] dL/d the base channels (sparse_objects)
  std::vector<float> dq_;          // [N, L]
  std::vector<float> d_wsum_;      // [N, Jf]
  LastLosses last_;
};

}  // namespace hgs::hybrid
