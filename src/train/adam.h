// Adam as in torch.optim.Adam (which 3DGS uses): per-parameter first/second moments and step count t (each
// update of a parameter advances its own t), bias-corrected update
// p -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps), eps = 1e-15 unless the parameter says otherwise,
// with a learning rate per column (SH DC and rest differ).
// One optimiser, two scopes: a per-Gaussian parameter is an array [N, dim] whose moment rows follow the
// Gaussians through densification (`gather`); an array parameter is any other array [rows, dim] (the hybrid
// method's view logits) that densification leaves alone. Every parameter knows where its values live
// (`values`), so checkpoints save and restore values and moments of every registered parameter generically.
// Wide per-Gaussian embeddings (the hybrid method's f_n, D = 512) use update_rows instead: row-sparse, the
// gradient of a row is produced on the fly (no [N, D] gradient buffer), the moments may be stored in bfloat16
// and the values in IEEE half (half the memory each; stochastic rounding keeps them unbiased, see core/half.h).
// Every update counts the non-finite gradient values it saw (`AdamParam::nonfinite`, an exponent test fused into
// the update loops): the trainer checks the counts after each step and stops naming the parameter group.
#pragma once
#include <cstdint>
#include <deque>
#include <functional>
#include <string>
#include <vector>

namespace hgs::train {

// Where a parameter's values live (not owned): float32 or IEEE half storage. A function, because the arrays it
// names may be reallocated (densification, checkpoint loads).
struct ParamValues {
  std::vector<float>* f32 = nullptr;
  std::vector<uint16_t>* f16 = nullptr;
};

enum class ParamScope { PerGaussian, Array };

struct AdamParam {
  std::string name;
  int dim = 1;
  ParamScope scope = ParamScope::PerGaussian;
  long step = 0;  // t of this parameter's last update
  float eps = 1e-15f;
  std::function<ParamValues()> values;  // null = not saved by checkpoints
  std::vector<float> lr;                // [dim] learning rate of each column (changed by schedules)
  std::vector<float> m, v;              // [N, dim] (float32 moments)
  bool bf16 = false;                    // moments stored in m16 / v16 instead of m / v
  std::vector<uint16_t> m16, v16;       // [N, dim] (bfloat16 moments)
  long nonfinite = 0;  // NaN / Inf gradient values seen by the updates since the last clear_nonfinite()
  void set_lr(float value) { lr.assign(dim, value); }
  size_t rows() const { return (bf16 ? m16.size() : m.size()) / size_t(dim); }
};

class Adam {
 public:
  float beta1 = 0.9f, beta2 = 0.999f;
  float lr_scale = 1.f;          // multiplies every learning rate (the batch rule of TrainConfig::batch_lr)
  std::deque<AdamParam> params;  // a deque: references returned by add() stay valid

  // A per-Gaussian parameter [n, dim] (moments zero).
  AdamParam& add(const std::string& name, int dim, int n, float lr, bool bf16 = false);
  // An array parameter [rows, dim] (not touched by densification).
  AdamParam& add_array(const std::string& name, int dim, int rows, float lr, float eps = 1e-15f);
  AdamParam& get(const std::string& name);  // throws if absent
  AdamParam* find(const std::string& name);
  const AdamParam* find(const std::string& name) const;
  // One update of `value` [N, dim] with gradient `grad` [N, dim] (advances p.step). Parallel (OpenMP), no
  // allocation.
  void update(AdamParam& p, float* value, const float* grad, int n) const;
  // Row-sparse ("lazy") update of `value` [N, dim], as torch.optim.SparseAdam: only rows that have a gradient
  // this step are touched; the other rows keep their value and moments. row_grad(i, g) writes row i's
  // gradient into g [dim] and returns false when the row has none (it is called once for every row, in
  // parallel, so it may also do other per-row work). Uses the parameter's first learning rate; works with
  // float32 or bfloat16 moments. Advances p.step once (the bias correction of every row uses it). Parallel
  // (OpenMP over rows), no allocation, deterministic.
  // `value` is float32 or IEEE half (uint16_t; written back with stochastic rounding, see core/half.h).
  template <class X, class RowGrad>
  void update_rows(AdamParam& p, X* value, int n, RowGrad&& row_grad) const;
  // One step that updates a single row (g [dim] is its gradient; advances p.step). X = float or uint16_t.
  template <class X>
  void update_row(AdamParam& p, X* value, long row, const float* g) const;
  // A row update's factors at step t: lr / (1 - b1^t), 1 / sqrt(1 - b2^t) (the same for every row of a step).
  struct RowStep {
    long t;
    float step, inv_sqrt_bc2;
  };
  RowStep row_step(const AdamParam& p, long t) const;
  // The per-row kernel at step s.t (does not advance p.step). Returns the number of non-finite values in g (the
  // caller adds them to p.nonfinite).
  template <class X>
  int row_kernel(AdamParam& p, X* value, long row, const float* g, const RowStep& s) const;
  // Row i of every per-Gaussian moment array becomes old row src[i], or zeros when fresh[i] (fresh may be
  // empty = none). Array parameters are left alone.
  void gather(const std::vector<int>& src, const std::vector<char>& fresh);
  // Zeroes both moments of one parameter (3DGS does this when it resets opacities).
  void reset_moments(const std::string& name);
  // The first parameter whose updates saw a non-finite gradient value since the last clear (null = none).
  const AdamParam* first_nonfinite() const;
  void clear_nonfinite();

 private:
  void check_rows(const AdamParam& p, int n) const;  // throws unless p holds n rows and dim <= kMaxRowUpdateDim
};

constexpr int kMaxRowUpdateDim = 4096;

// Whether the row updates with bfloat16 moments run 16 columns per instruction (AVX-512) or 8 (AVX2); the default
// is AVX-512 where the CPU has it. The same bits either way (tests compare them). set_adam_avx512(true) on a CPU
// without AVX-512 changes nothing and returns false.
bool set_adam_avx512(bool on);
bool adam_avx512();

template <class X, class RowGrad>
void Adam::update_rows(AdamParam& p, X* value, int n, RowGrad&& row_grad) const {
  check_rows(p, n);
  const RowStep s = row_step(p, ++p.step);
  long bad = 0;
#pragma omp parallel reduction(+ : bad)
  {
    alignas(64) float g[kMaxRowUpdateDim];
    // Chunks of 16 rows: the rows with a gradient cluster by index, so with chunks of 64 the last heavy chunks
    // kept a few threads busy while the rest waited (bench/project_threads.py, the full step at 320x240 / 30k on
    // 16 threads: 11.9x, with 16 rows 15.5x). 16 rows of D = 512 are still microseconds of work, far above what
    // the dynamic schedule costs per chunk.
#pragma omp for schedule(dynamic, 16)
    for (long i = 0; i < n; ++i)
      if (row_grad(i, g)) bad += row_kernel(p, value, i, g, s);
  }
  p.nonfinite += bad;
}

// 1 when x is NaN or +-Inf (an exponent test on the bits: vectorises, and survives -ffast-math).
inline int nonfinite_bit(float x) {
  uint32_t u;
  __builtin_memcpy(&u, &x, 4);
  return (u & 0x7f800000u) == 0x7f800000u;
}

}  // namespace hgs::train
