// GaussianModel: the trainable 3D Gaussians as a structure of float32 arrays (row i = Gaussian i), plus named
// extra per-Gaussian channel groups that later methods add (object associations, hard ids, language
// embeddings). Every per-Gaussian array is reachable through `fields()`, so densification, Adam and the PLY
// and checkpoint writers handle extra groups without knowing them.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace hgs {

struct ExtraGroup {
  std::string name;  // lower-case [a-z0-9_], e.g. "obj", "obj_id", "lang" (see docs/formats.md)
  int dim = 1;
  std::vector<float> data;  // [N, dim] (empty when f16)
  // Half-precision storage: the values live in `half` (IEEE binary16) instead of `data`. The hybrid trainer
  // keeps the language embeddings so (300k x 512 is 300 MB instead of 600 MB); readers that do not know the
  // group use value() / row(), and files always hold float32.
  bool f16 = false;
  std::vector<uint16_t> half;  // [N, dim] when f16

  float value(size_t k) const;           // element k, either storage
  void row(size_t i, float* out) const;  // row i as float32 [dim]
  std::vector<float> to_float() const;   // every value as float32 [N, dim]
};

// A named per-Gaussian array: `data` has N * dim floats.
struct Field {
  std::string name;
  int dim;
  std::vector<float>* data;
};

struct GaussianModel {
  int n = 0;
  int sh_degree = 3;                 // maximum SH degree stored (0..3)
  std::vector<float> mean;           // [N, 3]
  std::vector<float> log_scale;      // [N, 3]
  std::vector<float> quat;           // [N, 4] (w, x, y, z)
  std::vector<float> opacity_logit;  // [N]
  std::vector<float> sh;             // [N, S, 3], S = (sh_degree + 1)^2, coefficient-major then RGB
  std::vector<ExtraGroup> extras;

  int sh_stride() const { return (sh_degree + 1) * (sh_degree + 1); }
  // Base fields "mean", "log_scale", "quat", "opacity", "sh", then one per float32 extra group (by its name);
  // half-precision groups are not fields (resize, gather, validate, PLY and checkpoints handle them).
  std::vector<Field> fields();
  // Allocates every array for `count` Gaussians (zero-filled; quaternions identity).
  void resize(int count);
  // Adds an extra group filled with `fill` (half precision when f16); fails if the name exists. The reference
  // (like any into `extras`) is invalidated by the next add_extra.
  ExtraGroup& add_extra(const std::string& name, int dim, float fill = 0.f, bool f16 = false);
  ExtraGroup* find_extra(const std::string& name);
  const ExtraGroup* find_extra(const std::string& name) const;
  // Replaces the model by rows `src` of itself: row i of the result is old row src[i] (rows may repeat).
  // A compaction (src strictly increasing, as pruning gives) runs in place.
  void gather(const std::vector<int>& src);
  // Checks every array has the size implied by n, dim and sh_degree (throws hgs::Error naming `where`).
  void validate(const std::string& where) const;
};

// True when gathering rows `src` of an n-row array only moves rows towards the front (src strictly increasing,
// src[i] >= i): the gather can then run in place.
bool is_compaction(const std::vector<int>& src, int n);

// Row gather of one [n, d] array (model fields, Adam moments): row i becomes old row src[i], or zeros when
// fresh[i] (fresh may be empty = none). A compaction (pruning) runs in place, so the largest arrays are never
// held twice (the capacity is kept for later growth).
template <class V>
void gather_rows(V& a, int d, const std::vector<int>& src, const std::vector<char>& fresh = {}) {
  const bool any_fresh = std::find(fresh.begin(), fresh.end(), char(1)) != fresh.end();
  if (!any_fresh && is_compaction(src, int(a.size() / size_t(d)))) {
    for (size_t i = 0; i < src.size(); ++i)
      if (src[i] != int(i)) std::copy_n(a.data() + size_t(src[i]) * d, d, a.data() + i * d);
    a.resize(src.size() * d);
    return;
  }
  V t(src.size() * d, 0);
  for (size_t i = 0; i < src.size(); ++i)
    if (fresh.empty() || !fresh[i]) std::copy_n(a.data() + size_t(src[i]) * d, d, t.data() + i * d);
  a.swap(t);
}

constexpr float kSH_C0 = 0.28209479177387814f;
inline float rgb_to_sh(float c) { return (c - 0.5f) / kSH_C0; }
inline float sh_to_rgb(float s) { return s * kSH_C0 + 0.5f; }
inline float sigmoid(float x) { return 1.f / (1.f + std::exp(-x)); }
inline float inverse_sigmoid(float y) { return std::log(y / (1.f - y)); }

// 3DGS initialisation from SfM points: DC colour from the point colour, higher SH zero, isotropic scale
// sqrt(mean squared distance to the 3 nearest neighbours) (squared distance clamped at 1e-7), identity
// rotation, opacity 0.1. Fails when there are fewer than 4 points.
GaussianModel init_from_points(const std::vector<Eigen::Vector3f>& points,  // [P, 3]
                               const std::vector<Eigen::Vector3f>& colors,  // [P, 3] in [0, 1]
                               int sh_degree);

}  // namespace hgs
