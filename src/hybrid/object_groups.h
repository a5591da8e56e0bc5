// The object channels of eq. 6 as a base render plus sparse per-object groups: exact, and cheaper than the 4 J
// dense channels of object_channels.h because after fusion q_n is nearly one-hot.
//
// Every label no view observed Gaussian n in has s_{n,k} = 0, the smallest logit, so those labels share one
// value b_n = min_k q_{n,k} (object_channels.h). With delta_{n,k} = q_{n,k} - b_n,
//   I_k(p) = sum_n q_{n,k} c_n alpha T = B(p) + D_k(p),  B = sum_n b_n c_n alpha T,  D_k = sum_n delta_{n,k} c_n alpha
//   T,
// and the same for the opacities. The renderer composites B (and b_n alone, and the S other channels) as dense
// channels and D_k as sparse channel groups (render::ChannelsT::num_groups): Gaussian n has an entry for object
// j only where delta_{n,k} != 0 (k = objs[j]), or where the fusion backward needs its own dL/dq_{n,k} (s_{n,k} != 0
// on a Gaussian with a valid view); typically one entry, where the dense layout composites J groups of 4.
// Culled Gaussians (radius 0) get no entries: they reach no pixel.
//
// Backward: with g_k(p) = dL/dI_k(p) the renderer returns, per Gaussian, G_B = sum_p w sum_k g_k (the base
// colour channels, whose upstream gradient is sum_k g_k(p)) and G_e = sum_p w g_k for each entry. Then
//   dL/dc_n = b_n G_B + sum_e delta_e G_e,   dL/dq_{n,k} = c_n . G_e for the entries,
// and the labels without an entry share q = b_n and the remainder c_n . G_B - sum_e c_n . G_e. The fusion backward
// (fusion.h) needs their dL/dq only through sum_k q_k dL/dq_k (their own ds_k multiplies s_k = 0), so the
// remainder is given to one of them. (The opacity channels carry no gradient: BRO's band is a constant.)
//
// Layouts. Dense channels [N, 4 + S] (SparseLayout): base colour 0..2, the S others 3..3+S, b_n at 3 + S; the first
// 3 + S carry gradient. Groups [E, 4]: (delta c, delta). Renders come back as dense [H, W, 4 + S] and groups as
// one plane per object [J, H, W, 4] (render::ChannelsT::group_planes), which the object losses read as base +
// group (ObjectRenders::sparse, object_losses.h), each object's crop in place; the
// objects' colour gradients go back as the renderer's group gradients, which it reads on demand from the losses'
// sparse form (ObjectLosses::group_rows), and their sum is the base colour's.
#pragma once
#include <cstdint>
#include <vector>

#include "hybrid/object_channels.h"

namespace hgs::hybrid {

struct SparseLayout {
  int S = 0;
  static constexpr int base_color() { return 0; }
  static constexpr int other() { return 3; }
  int base_opacity() const { return 3 + S; }
  int grad_channels() const { return 3 + S; }
  int total() const { return 4 + S; }
};

struct ObjectGroups {
  static constexpr int kWidth = 4, kGradWidth = 3;
  std::vector<int> ptr;    // [N + 1]
  std::vector<int> id;     // [E] object position j in objs
  std::vector<float> val;  // [E, 4] (delta c, delta)
  std::vector<int> count;  // [N] scratch
};

// q [N, L], color [N, 3], radii [N] (0 = culled); s [N, L] and valid [N] from the fusion (null when the fusion
// backward does not run) -> dense [N, 4 + S] (the base channels; the S others untouched) and the groups. base [N]:
// base_association of each row of q when the caller has it (fuse() writes it with q), else null (computed here).
void build_object_groups(int n, int L, int J, const SparseLayout& sl, const int* objs, const float* q,
                         const float* color, const int* radii, const float* s, const uint8_t* valid, float* dense,
                         ObjectGroups& groups, const float* base = nullptr);

// grad_dense [N, 4 + S], grad_groups [E, 4] (the renderer's channel gradients) -> dq [N, L] and dcolor [N, 3]
// (both added). base as above.
void object_groups_backward(int n, int L, int J, const SparseLayout& sl, const int* objs, const float* q,
                            const float* color, const ObjectGroups& groups, const float* grad_dense,
                            const float* grad_groups, float* dq, float* dcolor, const float* base = nullptr);

}  // namespace hgs::hybrid
