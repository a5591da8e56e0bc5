// Object channels as base + sparse groups (object_groups.h has the derivation): building the entries and the
// backward to dq and dc.
#include "hybrid/object_groups.h"

#include <omp.h>

#include "core/parallel.h"

namespace hgs::hybrid {

namespace {

// Does Gaussian i get an entry for object j (label k)?
inline bool has_entry(const float* qi, float b, const float* si, bool fused, int k) {
  return qi[k] != b || (fused && si[k] != 0.f);
}

}  // namespace

void build_object_groups(int n, int L, int J, const SparseLayout& sl, const int* objs, const float* q,
                         const float* color, const int* radii, const float* s, const uint8_t* valid, float* dense,
                         ObjectGroups& g, const float* base) {
  const int C = sl.total();
  g.count.resize(n);
  g.ptr.resize(size_t(n) + 1);
  // Here and below on demand (demand_chunk): a visible Gaussian's entries are most of the work, and the visible
  // ones cluster by index once densification has appended its clones (a static split left threads idle).
#pragma omp parallel for schedule(dynamic, demand_chunk(n, 128))
  for (int i = 0; i < n; ++i) {
    const float* qi = q + size_t(i) * L;
    const float* ci = color + size_t(i) * 3;
    const float b = base ? base[i] : base_association(qi, L);
    float* d = dense + size_t(i) * C;
    d[0] = b * ci[0];
    d[1] = b * ci[1];
    d[2] = b * ci[2];
    d[sl.base_opacity()] = b;
    int cnt = 0;
    if (radii[i] > 0) {
      const bool fused = s && valid[i];
      const float* si = fused ? s + size_t(i) * L : nullptr;
      for (int j = 0; j < J; ++j) cnt += has_entry(qi, b, si, fused, objs[j]);
    }
    g.count[i] = cnt;
  }
  parallel_offsets(
      n, g.ptr.data(), [&](int i) { return g.count[i]; }, [](int, int) {});
  const size_t E = size_t(g.ptr[n]);
  g.id.resize(E);
  g.val.resize(E * ObjectGroups::kWidth);
#pragma omp parallel for schedule(dynamic, demand_chunk(n, 128))
  for (int i = 0; i < n; ++i) {
    if (g.count[i] == 0) continue;
    const float* qi = q + size_t(i) * L;
    const float* ci = color + size_t(i) * 3;
    const float b = base ? base[i] : base_association(qi, L);
    const bool fused = s && valid[i];
    const float* si = fused ? s + size_t(i) * L : nullptr;
    int e = g.ptr[i];
    for (int j = 0; j < J; ++j) {
      const int k = objs[j];
      if (!has_entry(qi, b, si, fused, k)) continue;
      const float dl = qi[k] - b;
      g.id[e] = j;
      float* v = &g.val[size_t(e) * ObjectGroups::kWidth];
      v[0] = dl * ci[0];
      v[1] = dl * ci[1];
      v[2] = dl * ci[2];
      v[3] = dl;
      ++e;
    }
  }
}

void object_groups_backward(int n, int L, int J, const SparseLayout& sl, const int* objs, const float* q,
                            const float* color, const ObjectGroups& g, const float* grad_dense,
                            const float* grad_groups, float* dq, float* dcolor, const float* base) {
  const int C = sl.total();
#pragma omp parallel for schedule(dynamic, demand_chunk(n, 128))
  for (int i = 0; i < n; ++i) {
    const float* qi = q + size_t(i) * L;
    const float* ci = color + size_t(i) * 3;
    const float* gb = grad_dense + size_t(i) * C;
    const float b = base ? base[i] : base_association(qi, L);
    float* dc = dcolor + size_t(i) * 3;
    float* dqi = dq + size_t(i) * L;
    dc[0] += b * gb[0];
    dc[1] += b * gb[1];
    dc[2] += b * gb[2];
    float rest = ci[0] * gb[0] + ci[1] * gb[1] + ci[2] * gb[2];  // sum_k dL/dq_k over the present labels
    for (int e = g.ptr[i]; e < g.ptr[i + 1]; ++e) {
      const int j = g.id[e];
      const float* ge = grad_groups + size_t(e) * ObjectGroups::kWidth;
      const float dl = qi[objs[j]] - b;
      dc[0] += dl * ge[0];
      dc[1] += dl * ge[1];
      dc[2] += dl * ge[2];
      const float dqe = ci[0] * ge[0] + ci[1] * ge[1] + ci[2] * ge[2];
      dqi[objs[j]] += dqe;
      rest -= dqe;
    }
    // The labels without an entry (all at q = b_n): their summed gradient goes to the first of them. Entries are
    // in ascending object order (build_object_groups), so one walk beside them finds it.
    int e = g.ptr[i];
    for (int j = 0; j < J; ++j) {
      if (e < g.ptr[i + 1] && g.id[e] == j) {
        ++e;
        continue;
      }
      dqi[objs[j]] += rest;
      break;
    }
  }
}

}  // namespace hgs::hybrid
