// Object-conditioned channels for one view (paper eqs. 6 and 11), composited by the engine in one pass.
//
// For the J objects present in the view, objs[j] in 0..K, every Gaussian gets 4 J extra channels,
//   q_{n,k} c_n (3 colour channels) and q_{n,k} (opacity),   k = objs[j],
// so one rasterization yields every object render I^pred_{u,k} = sum_n q_{n,k} c_n alpha T and its opacity
// A^pred_{u,k} = sum_n q_{n,k} alpha T, instead of K + 1 separate rasterizations. Objects absent from the
// view's mask are skipped.
//
// Channel layout (ObjectLayout), with S further channels that carry gradient (the no-SCL ablation's semantic
// render) between them:
//   [0, 3J)            colours, object j at 3j .. 3j+2
//   [3J, 3J+S)         the S other channels
//   [3J+S, 4J+S)       opacities, object j at 3J+S+j
//   [4J+S, 4J+S+4)     with `base`: the base render (b_n c_n, b_n), b_n = min_k q_{n,k} over all L labels
// The opacities come last because training uses them only through BRO's band, a constant: the renderer's
// backward is told that only the first grad_channels() carry gradient and skips the rest.
// The base render: after fusion q_n is softmax(s_n / T) and every label no view observed the Gaussian in has
// s_{n,k} = 0, the smallest logit, so all those labels share one value b_n, the row's minimum. Wherever no
// Gaussian with q_{n,k} != b_n reaches a pixel, object k's render there equals the base render bitwise (the same
// products summed in the same order), so the object losses can score such pixels once for every object
// (object_losses.h). The base channels are forward-only.
#pragma once
#include <cstddef>

namespace hgs::hybrid {

struct ObjectLayout {
  int J = 0;          // objects
  int S = 0;          // other channels with gradient
  bool base = false;  // the 4 base channels follow the opacities
  int color(int j) const { return 3 * j; }
  int other() const { return 3 * J; }
  int opacity(int j) const { return 3 * J + S + j; }
  int base_color() const { return 4 * J + S; }  // 3 channels
  int base_opacity() const { return 4 * J + S + 3; }
  int grad_channels() const { return 3 * J + S; }
  int total() const { return 4 * J + S + (base ? 4 : 0); }
};

// b_n of the base render: the smallest of a Gaussian's L association values. q_n [L]
template <class T>
T base_association(const T* q, int L) {
  T b = q[0];
  for (int k = 1; k < L; ++k) b = q[k] < b ? q[k] : b;
  return b;
}

// q [N, L], color [N, 3] -> extra [N, lay.total()] (the colour, opacity and base channels; the S others
// untouched).
template <class T>
void object_channels(int n, int L, const ObjectLayout& lay, const int* objs, const T* q, const T* color, T* extra) {
  const int C = lay.total(), J = lay.J;
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    T* e = extra + size_t(i) * C;
    const T* c = color + size_t(i) * 3;
    for (int j = 0; j < J; ++j) {
      const T w = q[size_t(i) * L + objs[j]];
      e[lay.color(j)] = w * c[0];
      e[lay.color(j) + 1] = w * c[1];
      e[lay.color(j) + 2] = w * c[2];
      e[lay.opacity(j)] = w;
    }
    if (lay.base) {
      const T b = base_association(q + size_t(i) * L, L);
      e[lay.base_color()] = b * c[0];
      e[lay.base_color() + 1] = b * c[1];
      e[lay.base_color() + 2] = b * c[2];
      e[lay.base_opacity()] = b;
    }
  }
}

// d_extra [N, lay.total()] -> dq [N, L] (added), dcolor [N, 3] (added).
template <class T>
void object_channels_backward(int n, int L, const ObjectLayout& lay, const int* objs, const T* q, const T* color,
                              const T* d_extra, T* dq, T* dcolor) {
  const int C = lay.total(), J = lay.J;
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const T* g = d_extra + size_t(i) * C;
    const T* c = color + size_t(i) * 3;
    T* dc = dcolor + size_t(i) * 3;
    for (int j = 0; j < J; ++j) {
      const T w = q[size_t(i) * L + objs[j]];
      const T* gc = g + lay.color(j);
      dq[size_t(i) * L + objs[j]] += gc[0] * c[0] + gc[1] * c[1] + gc[2] * c[2] + g[lay.opacity(j)];
      dc[0] += gc[0] * w;
      dc[1] += gc[1] * w;
      dc[2] += gc[2] * w;
    }
  }
}

}  // namespace hgs::hybrid
