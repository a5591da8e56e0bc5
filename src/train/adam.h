// Adam as in torch.optim.Adam (which 3DGS uses): per-parameter first/second moments, one shared step count,
// bias-corrected update p -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps), eps = 1e-15. Every
// parameter is a per-Gaussian array [N, dim] with a learning rate per column (SH DC and rest differ), so the
// moments can follow Gaussians through densification (`gather`).
#pragma once
#include <string>
#include <vector>

namespace hgs::train {

struct AdamParam {
  std::string name;
  int dim = 1;
  std::vector<float> lr;    // [dim] learning rate of each column (changed by schedules)
  std::vector<float> m, v;  // [N, dim]
  void set_lr(float value) { lr.assign(dim, value); }
};

class Adam {
 public:
  float beta1 = 0.9f, beta2 = 0.999f, eps = 1e-15f;
  long step_count = 0;  // t of the last update
  std::vector<AdamParam> params;

  AdamParam& add(const std::string& name, int dim, int n, float lr);
  AdamParam& get(const std::string& name);  // throws if absent
  AdamParam* find(const std::string& name);
  // Advances t; call once per iteration before the update()s.
  void begin_step() { ++step_count; }
  // One update of `value` [N, dim] with gradient `grad` [N, dim]. Parallel (OpenMP), no allocation.
  void update(AdamParam& p, float* value, const float* grad, int n) const;
  // Row i of every moment array becomes old row src[i], or zeros when fresh[i] (fresh may be empty = none).
  void gather(const std::vector<int>& src, const std::vector<char>& fresh);
  // Zeroes both moments of one parameter (3DGS does this when it resets opacities).
  void reset_moments(const std::string& name);
};

}  // namespace hgs::train
