// Object-conditioned channels for one view (paper eqs. 6 and 11), composited by the engine in one pass.
//
// For the J objects present in the view, objs[j] in 0..K, every Gaussian gets 4 J extra channels
//   (q_{n,k} c_n^r, q_{n,k} c_n^g, q_{n,k} c_n^b, q_{n,k}),   k = objs[j],
// so one rasterization yields every object render I^pred_{u,k} = sum_n q_{n,k} c_n alpha T and its opacity
// A^pred_{u,k} = sum_n q_{n,k} alpha T, instead of K + 1 separate rasterizations. Objects absent from the
// view's mask are skipped.
#pragma once
#include <cstddef>

namespace hgs::hybrid {

constexpr int kChannelsPerObject = 4;

// q [N, L], color [N, 3] -> extra [N, stride] (channels 4j..4j+3 written; stride >= 4 J).
template <class T>
void object_channels(int n, int L, int J, const int* objs, const T* q, const T* color, int stride, T* extra) {
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    T* e = extra + size_t(i) * stride;
    const T* c = color + size_t(i) * 3;
    for (int j = 0; j < J; ++j) {
      const T w = q[size_t(i) * L + objs[j]];
      e[4 * j] = w * c[0];
      e[4 * j + 1] = w * c[1];
      e[4 * j + 2] = w * c[2];
      e[4 * j + 3] = w;
    }
  }
}

// d_extra [N, stride] -> dq [N, L] (added), dcolor [N, 3] (added).
template <class T>
void object_channels_backward(int n, int L, int J, const int* objs, const T* q, const T* color, int stride,
                              const T* d_extra, T* dq, T* dcolor) {
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const T* g = d_extra + size_t(i) * stride;
    const T* c = color + size_t(i) * 3;
    T* dc = dcolor + size_t(i) * 3;
    for (int j = 0; j < J; ++j) {
      const T w = q[size_t(i) * L + objs[j]];
      dq[size_t(i) * L + objs[j]] += g[4 * j] * c[0] + g[4 * j + 1] * c[1] + g[4 * j + 2] * c[2] + g[4 * j + 3];
      dc[0] += g[4 * j] * w;
      dc[1] += g[4 * j + 1] * w;
      dc[2] += g[4 * j + 2] * w;
    }
  }
}

}  // namespace hgs::hybrid
