// Real spherical harmonics colour (3DGS convention, degree 0..3) per view direction, forward and exact backward.
//
// colour_c = max(sum_k B_k(d) sh[k, c] + 0.5, 0) with d = normalise(mean - campos) and B_k the 3DGS basis
// (constants C0..C3 of the reference implementation). Backward gives dL/dsh for the active coefficients and
// dL/dmean through the direction (basis derivative, then the normalisation); clamped channels pass no gradient.
// Templated on the scalar so tests run it in double; the production path is T = float, which sh.cpp runs 8
// Gaussians at a time by instantiating these same templates on a pack of 8 floats (compiled without FMA
// contraction, so its bits are those of T = float one Gaussian at a time; test_sh_simd.cpp).
#pragma once
#include <cmath>

namespace hgs::render {

constexpr int kMaxShCoeffs = 16;

inline constexpr int sh_num_coeffs(int degree) { return (degree + 1) * (degree + 1); }

// The two steps of the per-Gaussian templates below that are not plain arithmetic, as functions so the templates
// also run on sh.cpp's pack of 8 Gaussians (one float lane each), which overloads them lane-wise.
template <class T>
inline T sh_sqrt(T x) {
  return std::sqrt(x);
}
template <class T>
inline T sh_if_positive(T c, T a, T b) {  // c > 0 ? a : b
  return c > T(0) ? a : b;
}

// Basis values b [16] at unit direction (x, y, z) and, when db != null, their derivatives db [16, 3].
template <class T>
inline void sh_basis(int degree, T x, T y, T z, T* b, T* db) {
  const T C0 = T(0.28209479177387814), C1 = T(0.4886025119029199);
  const T C2[5] = {T(1.0925484305920792), T(-1.0925484305920792), T(0.31539156525252005), T(-1.0925484305920792),
                   T(0.5462742152960396)};
  const T C3[7] = {T(-0.5900435899266435), T(2.890611442640554), T(-0.4570457994644658), T(0.3731763325901154),
                   T(-0.4570457994644658), T(1.445305721320277), T(-0.5900435899266435)};
  b[0] = C0;
  if (db) db[0] = db[1] = db[2] = 0;
  if (degree < 1) return;
  b[1] = -C1 * y;
  b[2] = C1 * z;
  b[3] = -C1 * x;
  if (db) {
    db[3] = 0, db[4] = -C1, db[5] = 0;
    db[6] = 0, db[7] = 0, db[8] = C1;
    db[9] = -C1, db[10] = 0, db[11] = 0;
  }
  if (degree < 2) return;
  const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
  b[4] = C2[0] * xy;
  b[5] = C2[1] * yz;
  b[6] = C2[2] * (2 * zz - xx - yy);
  b[7] = C2[3] * xz;
  b[8] = C2[4] * (xx - yy);
  if (db) {
    T* d = db + 12;
    d[0] = C2[0] * y, d[1] = C2[0] * x, d[2] = 0;
    d[3] = 0, d[4] = C2[1] * z, d[5] = C2[1] * y;
    d[6] = -2 * C2[2] * x, d[7] = -2 * C2[2] * y, d[8] = 4 * C2[2] * z;
    d[9] = C2[3] * z, d[10] = 0, d[11] = C2[3] * x;
    d[12] = 2 * C2[4] * x, d[13] = -2 * C2[4] * y, d[14] = 0;
  }
  if (degree < 3) return;
  b[9] = C3[0] * y * (3 * xx - yy);
  b[10] = C3[1] * xy * z;
  b[11] = C3[2] * y * (4 * zz - xx - yy);
  b[12] = C3[3] * z * (2 * zz - 3 * xx - 3 * yy);
  b[13] = C3[4] * x * (4 * zz - xx - yy);
  b[14] = C3[5] * z * (xx - yy);
  b[15] = C3[6] * x * (xx - 3 * yy);
  if (db) {
    T* d = db + 27;
    d[0] = 6 * C3[0] * xy, d[1] = C3[0] * (3 * xx - 3 * yy), d[2] = 0;
    d[3] = C3[1] * yz, d[4] = C3[1] * xz, d[5] = C3[1] * xy;
    d[6] = -2 * C3[2] * xy, d[7] = C3[2] * (4 * zz - xx - 3 * yy), d[8] = 8 * C3[2] * yz;
    d[9] = -6 * C3[3] * xz, d[10] = -6 * C3[3] * yz, d[11] = C3[3] * (6 * zz - 3 * xx - 3 * yy);
    d[12] = C3[4] * (4 * zz - 3 * xx - yy), d[13] = -2 * C3[4] * xy, d[14] = 8 * C3[4] * xz;
    d[15] = 2 * C3[5] * xz, d[16] = -2 * C3[5] * yz, d[17] = C3[5] * (xx - yy);
    d[18] = C3[6] * (3 * xx - 3 * yy), d[19] = -6 * C3[6] * xy, d[20] = 0;
  }
}

// Colour of one Gaussian: sh [S, 3] (first (degree+1)^2 rows used), unnormalised direction dir [3].
// color [3] = max(raw + 0.5, 0); raw [3] (optional) receives the value before the clamp.
template <class T>
inline void sh_eval_one(int degree, const T* sh, const T* dir, T* color, T* raw = nullptr) {
  const T len = sh_sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  const T il = sh_if_positive(len, T(1) / len, T(0));
  T b[kMaxShCoeffs];
  sh_basis(degree, dir[0] * il, dir[1] * il, dir[2] * il, b, (T*)nullptr);
  const int K = sh_num_coeffs(degree);
  for (int c = 0; c < 3; ++c) {
    T v = 0;
    for (int k = 0; k < K; ++k) v += b[k] * sh[3 * k + c];
    v += T(0.5);
    if (raw) raw[c] = v;
    color[c] = sh_if_positive(v, v, T(0));
  }
}

// Backward of sh_eval_one: dcolor [3] upstream. Writes dsh [S, 3] for the active rows (others untouched) and
// adds dL/d(dir) to ddir [3].
template <class T>
inline void sh_backward_one(int degree, const T* sh, const T* dir, const T* dcolor, T* dsh, T* ddir) {
  const T len = sh_sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  const T il = sh_if_positive(len, T(1) / len, T(0));
  const T n[3] = {dir[0] * il, dir[1] * il, dir[2] * il};
  T b[kMaxShCoeffs], db[kMaxShCoeffs * 3];
  sh_basis(degree, n[0], n[1], n[2], b, db);
  const int K = sh_num_coeffs(degree);
  T g[3];
  for (int c = 0; c < 3; ++c) {
    T v = 0;
    for (int k = 0; k < K; ++k) v += b[k] * sh[3 * k + c];
    g[c] = sh_if_positive(v + T(0.5), dcolor[c], T(0));  // clamp at 0 passes no gradient
  }
  T dn[3] = {0, 0, 0};
  for (int k = 0; k < K; ++k) {
    const T gk = g[0] * sh[3 * k] + g[1] * sh[3 * k + 1] + g[2] * sh[3 * k + 2];
    for (int c = 0; c < 3; ++c) dsh[3 * k + c] = b[k] * g[c];
    dn[0] += gk * db[3 * k];
    dn[1] += gk * db[3 * k + 1];
    dn[2] += gk * db[3 * k + 2];
  }
  const T dot = dn[0] * n[0] + dn[1] * n[1] + dn[2] * n[2];
  for (int j = 0; j < 3; ++j) ddir[j] += (dn[j] - n[j] * dot) * il;
}

// Array forward: colors [N, 3] for Gaussians with active[i] != 0 (all when active is null; others set to 0).
template <class T>
void sh_forward(int n, int degree, int stride,
                const T* sh,        // [N, stride, 3]
                const T* mean,      // [N, 3]
                const T* campos,    // [3]
                const int* active,  // [N] or null (e.g. radii: nonzero = evaluate)
                T* colors);         // [N, 3] out

// Array backward: dsh [N, stride, 3] overwritten (zero beyond the active degree and for inactive Gaussians);
// dL/dmean through the view direction is ADDED to dmean [N, 3] when dmean is not null.
template <class T>
void sh_backward(int n, int degree, int stride,
                 const T* sh,        // [N, stride, 3]
                 const T* mean,      // [N, 3]
                 const T* campos,    // [3]
                 const int* active,  // [N] or null
                 const T* dcolors,   // [N, 3]
                 T* dsh,             // [N, stride, 3] out
                 T* dmean);          // [N, 3] accumulated, or null

extern template void sh_forward<float>(int, int, int, const float*, const float*, const float*, const int*, float*);
extern template void sh_forward<double>(int, int, int, const double*, const double*, const double*, const int*,
                                        double*);
extern template void sh_backward<float>(int, int, int, const float*, const float*, const float*, const int*,
                                        const float*, float*, float*);
extern template void sh_backward<double>(int, int, int, const double*, const double*, const double*, const int*,
                                         const double*, double*, double*);

}  // namespace hgs::render
