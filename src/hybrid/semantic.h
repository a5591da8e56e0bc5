// The semantic term of one view. With SCL (eqs. 9-10): pooled object predictions P_k = sum_n q f a / m from
// the renderer's pixel-weighted sums a_{n,k} = sum_p M_k alpha T, InfoNCE of each anchor object against the
// pooled references of another view holding it (positive) and that view's other SCL classes (negatives: its
// other objects, and its background under config.h's scl_background rule); one pass
// over the Gaussians then forms dq and da (with sem_geometry only). f's gradient df_n = sum_j q a G_j is not
// formed per view: the view is kept in factored form (its objects, G [Jf, D] and the non-zero rows of a), and
// at the step's end one row-sparse Adam step of f ("lang", a registered per-Gaussian parameter with its own step
// count) forms each row's df from every view of the step (no [N, D] gradient buffer). With MPI the factored
// views are what the ranks exchange: Jf x D + rows x (Jf + 1) numbers per view instead of rows x D. Without SCL
// (the ablation): 1 - cos between the full semantic render sum f alpha T (extra channels) and the upsampled
// reference features, f updated from the renderer's channel gradients summed over the step's views.
#pragma once
#include <random>
#include <vector>

#include "core/scratch_vector.h"
#include "hybrid/config.h"
#include "hybrid/data.h"
#include "hybrid/fields.h"
#include "hybrid/object_channels.h"
#include "train/adam.h"
#include "train/reducer.h"

namespace hgs::hybrid {

// One InfoNCE anchor: SCL class classes_u[j] of view u with its positive's view v.
struct SclAnchor {
  int j, v;
};
// The anchors of view u: every class of classes_u that another view's SCL classes hold, its positive view drawn
// uniformly among those other views. views_with [L]: ascending training views whose SCL classes hold each label
// (u's own classes are in their lists). Classes held by no other view are skipped.
std::vector<SclAnchor> draw_scl_anchors(const std::vector<int>& classes_u,
                                        const std::vector<std::vector<int>>& views_with, int u, std::mt19937_64& rng);

struct SemanticValues {
  double loss = 0;  // mean InfoNCE over the anchors, or the mean cosine loss
  int anchors = 0;
};

class SemanticPass {
 public:
  static constexpr const char* kParam = "lang";  // f's optimiser parameter

  SemanticPass(const HybridConfig& cfg, const HybridData* data);
  void set_config(const HybridConfig& cfg) { cfg_ = cfg; }
  // SCL anchors of view u (empty when SCL is off or lambda_sem = 0): their labels, whose hard masks
  // M_j(p) = [label(p) = anchors[j]] in the view's label image (data's masks[u].labels) are the renderer's
  // pixel-weight maps (RenderSettings::pixel_labels). The list is the data's own (valid while the data is).
  const std::vector<int>& anchors_of(int u);
  // SCL. weight_sums [N, Jf]; adds lambda_sem * d/dq to dq [N, L]; da [N, Jf] (null = no gradient to the
  // pooled weights); keeps the view's factored f gradient for update() (first = the step's first view).
  SemanticValues contrastive(int u, int n, HybridFields& h, const float* weight_sums, float* dq, float* da,
                             std::mt19937_64& rng, bool first);
  // No-SCL ablation: loss on the render's channels [o, o + D) of extra [H, W, C]; writes lambda_sem * d/d
  // into the same channels of d_extra.
  SemanticValues cosine(int u, int W, int H, const float* extra, int C, int o, float* d_extra);
  // No-SCL ablation: adds the renderer's gradient of f's channels (grad_extra [N, C]) to the step's sum.
  void add_channel_grads(int n, const float* grad_extra, int C, int o, bool first);
  // After the step's last view: every rank gets every rank's factored views (SCL) or the sum of the channel
  // gradients (no SCL), in rank order.
  void reduce(train::Reducer& r);
  // f's row-sparse Adam step with the step's gradient x scale (1 / G); nothing when no view had one.
  void update(int n, HybridFields& h, train::Adam& optim, float scale);
  void release() { std::vector<float>().swap(fgrad_); }  // per-step buffers (before densification)

 private:
  HybridConfig cfg_;
  const HybridData* data_;
  int L_, D_;
  std::vector<std::vector<int>> views_with_;  // [L] training views whose SCL objects include l
  std::vector<int> classes_;
  std::vector<float> P_, dP_, G_;          // [Jf, D] predictions, their gradient, dP / (m + eps)
  std::vector<float> refs_;                // [R, D] InfoNCE candidates of one anchor
  std::vector<std::vector<int>> touched_;  // per chunk of rows: the rows a view's masks touched (kept for capacity)
  // One view's f gradient in factored form: df_n = sum_j q_{n,objs[j]} a_{n,j} G_j.
  struct FactoredView {
    std::vector<int> objs;  // [Jf]
    std::vector<float> G;   // [Jf, D]
    // (ScratchVector: every element is written before it is read; a zeroing resize was a serial pass over
    // rows x (Jf + 1) values in every step, 0.8 ms at 300k Gaussians.)
    ScratchVector<int> rows;  // Gaussians with a non-zero a
    ScratchVector<float> a;   // [rows, Jf]
  };
  std::vector<FactoredView> views_;  // the step's (after reduce: every rank's, in global order)
  std::vector<float> fgrad_;         // [N, D] no-SCL ablation: the step's channel-gradient sum
  bool fgrad_set_ = false;
};

}  // namespace hgs::hybrid
