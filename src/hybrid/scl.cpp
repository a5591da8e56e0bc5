#include "hybrid/scl.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace hgs::hybrid {

template <class T>
T normalize(T* v, int D) {
  T s = 0;
  for (int d = 0; d < D; ++d) s += v[d] * v[d];
  T nrm = std::sqrt(s);
  if (nrm > T(0))
    for (int d = 0; d < D; ++d) v[d] /= nrm;
  return nrm;
}

template <class T>
void pooled_prediction(int n, int D, int L, int J, const T* q, const T* f, const T* a, const int* objs, const T* mass,
                       T eps, T* P) {
  pooled_prediction_rows(
      n, D, L, J, q, [&](long i, T*) { return f + size_t(i) * D; }, a, objs, mass, eps, P);
}

template <class T>
void pooled_prediction_backward(int n, int D, int L, int J, const T* q, const T* f, const T* a, const int* objs,
                                const T* mass, T eps, const T* dP, T* dq, T* df, T* da) {
  std::vector<T> g(size_t(J) * D);
  pooled_row_factors(J, D, dP, mass, eps, g.data());
  // Row by row (pooled_backward_row and pooled_df_row, which the trainer also calls); df is added here.
#pragma omp parallel
  {
    std::vector<T> row(D);
#pragma omp for schedule(static)
    for (int i = 0; i < n; ++i) {
      pooled_backward_row(long(i), D, L, J, q, f + size_t(i) * D, a, objs, g.data(), dq, da);
      if (!df || !pooled_df_row(D, J, q + size_t(i) * L, a + size_t(i) * J, objs, g.data(), row.data(), false))
        continue;
      T* dfi = df + size_t(i) * D;
      for (int d = 0; d < D; ++d) dfi[d] += row[d];
    }
  }
}

template <class T>
T info_nce(const T* p, int D, const T* refs, int R, int positive, T tau2, T* dp, T scale) {
  std::vector<T> u(p, p + D);
  const T nrm = normalize(u.data(), D);
  std::vector<T> logit(R);
  T mx = -1e30;
  for (int r = 0; r < R; ++r) {
    T s = 0;
    for (int d = 0; d < D; ++d) s += u[d] * refs[size_t(r) * D + d];
    logit[r] = s / tau2;
    mx = std::max(mx, logit[r]);
  }
  T z = 0;
  for (int r = 0; r < R; ++r) z += std::exp(logit[r] - mx);
  const T loss = -(logit[positive] - mx - std::log(z));
  if (dp && nrm > T(0)) {
    // dL/du = sum_r (softmax_r - [r = pos]) refs_r / tau2; then through u = p / |p|.
    std::vector<T> du(D, T(0));
    for (int r = 0; r < R; ++r) {
      const T c = (std::exp(logit[r] - mx) / z - (r == positive ? T(1) : T(0))) / tau2;
      for (int d = 0; d < D; ++d) du[d] += c * refs[size_t(r) * D + d];
    }
    T ud = 0;
    for (int d = 0; d < D; ++d) ud += u[d] * du[d];
    for (int d = 0; d < D; ++d) dp[d] += scale * (du[d] - u[d] * ud) / nrm;
  }
  return loss;
}

template <class T>
T cosine_loss(const T* S, int stride, const T* R, size_t P, int D, T* grad, T scale) {
  return cosine_loss_rows(
      S, stride, [R, D](size_t p, T*) { return R + p * D; }, P, D, grad, scale);
}

template float cosine_loss<float>(const float*, int, const float*, size_t, int, float*, float);
template double cosine_loss<double>(const double*, int, const double*, size_t, int, double*, double);
template float normalize<float>(float*, int);
template double normalize<double>(double*, int);
template void pooled_prediction<float>(int, int, int, int, const float*, const float*, const float*, const int*,
                                       const float*, float, float*);
template void pooled_prediction<double>(int, int, int, int, const double*, const double*, const double*, const int*,
                                        const double*, double, double*);
template void pooled_prediction_backward<float>(int, int, int, int, const float*, const float*, const float*,
                                                const int*, const float*, float, const float*, float*, float*, float*);
template void pooled_prediction_backward<double>(int, int, int, int, const double*, const double*, const double*,
                                                 const int*, const double*, double, const double*, double*, double*,
                                                 double*);
template float info_nce<float>(const float*, int, const float*, int, int, float, float*, float);
template double info_nce<double>(const double*, int, const double*, int, int, double, double*, double);

}  // namespace hgs::hybrid
