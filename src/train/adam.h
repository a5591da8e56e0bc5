// Adam as in torch.optim.Adam (which 3DGS uses): per-parameter first/second moments, one shared step count,
// bias-corrected update p -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps), eps = 1e-15. Every
// parameter is a per-Gaussian array [N, dim] with a learning rate per column (SH DC and rest differ), so the
// moments can follow Gaussians through densification (`gather`).
// Wide per-Gaussian embeddings (the hybrid method's f_n, D = 512) use update_rows instead: row-sparse, the
// gradient of a row is produced on the fly (no [N, D] gradient buffer), the moments may be stored in bfloat16
// and the values in IEEE half (half the memory each; stochastic rounding keeps them unbiased, see core/half.h).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace hgs::train {

struct AdamParam {
  std::string name;
  int dim = 1;
  std::vector<float> lr;    // [dim] learning rate of each column (changed by schedules)
  std::vector<float> m, v;  // [N, dim] (float32 moments)
  bool bf16 = false;        // moments stored in m16 / v16 instead of m / v
  std::vector<uint16_t> m16, v16;  // [N, dim] (bfloat16 moments)
  void set_lr(float value) { lr.assign(dim, value); }
  size_t rows() const { return (bf16 ? m16.size() : m.size()) / size_t(dim); }
};

class Adam {
 public:
  float beta1 = 0.9f, beta2 = 0.999f, eps = 1e-15f;
  long step_count = 0;  // t of the last update
  std::vector<AdamParam> params;

  AdamParam& add(const std::string& name, int dim, int n, float lr, bool bf16 = false);
  AdamParam& get(const std::string& name);  // throws if absent
  AdamParam* find(const std::string& name);
  // Advances t; call once per iteration before the update()s.
  void begin_step() { ++step_count; }
  // One update of `value` [N, dim] with gradient `grad` [N, dim]. Parallel (OpenMP), no allocation.
  void update(AdamParam& p, float* value, const float* grad, int n) const;
  // Row-sparse ("lazy") update of `value` [N, dim], as torch.optim.SparseAdam: only rows that have a gradient
  // this step are touched; the other rows keep their value and moments. row_grad(i, g) writes row i's
  // gradient into g [dim] and returns false when the row has none (it is called once for every row, in
  // parallel, so it may also do other per-row work). Uses the parameter's first learning rate; works with
  // float32 or bfloat16 moments. `t` is the step for the bias correction (0 = step_count; a caller that updates
  // before begin_step() passes step_count + 1). Parallel (OpenMP over rows), no allocation, deterministic.
  // `value` is float32 or IEEE half (uint16_t; written back with stochastic rounding, see core/half.h).
  template <class X, class RowGrad>
  void update_rows(AdamParam& p, X* value, int n, RowGrad&& row_grad, long t = 0) const;
  // The per-row kernel of update_rows (g [dim] is the row's gradient). X = float or uint16_t (half).
  template <class X>
  void update_row(AdamParam& p, X* value, long row, const float* g, long t = 0) const;
  // Row i of every moment array becomes old row src[i], or zeros when fresh[i] (fresh may be empty = none).
  void gather(const std::vector<int>& src, const std::vector<char>& fresh);
  // Zeroes both moments of one parameter (3DGS does this when it resets opacities).
  void reset_moments(const std::string& name);

 private:
  void check_rows(const AdamParam& p, int n) const;  // throws unless p holds n rows and dim <= kMaxRowUpdateDim
};

constexpr int kMaxRowUpdateDim = 4096;

template <class X, class RowGrad>
void Adam::update_rows(AdamParam& p, X* value, int n, RowGrad&& row_grad, long t) const {
  check_rows(p, n);
#pragma omp parallel
  {
    alignas(64) float g[kMaxRowUpdateDim];
#pragma omp for schedule(dynamic, 64)
    for (long i = 0; i < n; ++i)
      if (row_grad(i, g)) update_row(p, value, i, g, t);
  }
}

}  // namespace hgs::train
