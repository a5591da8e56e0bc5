// The projection of project.h on 8-lane packs (render/simd.h): lanes::Ops for simd::Pack<float> (the float
// renderer's path, 8 Gaussians per vector, project.cpp) and simd::Pack<double> (a test path, each lane the
// scalar double functions). exp of a float pack is simd::vexp (Cephes polynomial, about 1 ulp); sqrt, ceil and
// floor are the correctly rounded instructions, as the scalar functions.
#pragma once
#include "render/project.h"
#include "render/simd.h"

namespace hgs::render::lanes {

template <>
struct Ops<simd::Pack<float>> {
  using V = simd::Pack<float>;
  using S = float;
  using M = simd::Mask<float>;
  static V sqrt(V x) {
#if defined(__AVX2__)  // immintrin.h comes with simd.h for AVX2 builds
    return (V)_mm256_sqrt_ps((__m256)x);
#else
    for (int l = 0; l < simd::kLanes; ++l) x[l] = std::sqrt(x[l]);
    return x;
#endif
  }
  static V exp(V x) { return simd::vexp(x); }
  static V ceil(V x) {
#if defined(__AVX2__)
    return (V)_mm256_round_ps((__m256)x, _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC);
#else
    for (int l = 0; l < simd::kLanes; ++l) x[l] = std::ceil(x[l]);
    return x;
#endif
  }
  static V floor(V x) {
#if defined(__AVX2__)
    return (V)_mm256_round_ps((__m256)x, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
#else
    for (int l = 0; l < simd::kLanes; ++l) x[l] = std::floor(x[l]);
    return x;
#endif
  }
};

template <>
struct Ops<simd::Pack<double>> {
  using V = simd::Pack<double>;
  using S = double;
  using M = simd::Mask<double>;
  static V sqrt(V x) {
    for (int l = 0; l < simd::kLanes; ++l) x[l] = std::sqrt(x[l]);
    return x;
  }
  static V exp(V x) { return simd::vexp(x); }  // std::exp per lane
  static V ceil(V x) {
    for (int l = 0; l < simd::kLanes; ++l) x[l] = std::ceil(x[l]);
    return x;
  }
  static V floor(V x) {
    for (int l = 0; l < simd::kLanes; ++l) x[l] = std::floor(x[l]);
    return x;
  }
};

}  // namespace hgs::render::lanes

namespace hgs::render {

// Array drivers on packs: Gaussians [i0, i0 + 8) per pack (the last pack padded), results as project_forward /
// project_backward. Declared here for the tests, which run them on double packs against the scalar path.
template <class T>
int project_forward_packs(const CameraT<T>& cam, int n, const T* mean, const T* log_scale, const T* quat, T* mean2d,
                          T* conic, T* depth, int* radius);
template <class T>
void project_backward_packs(const CameraT<T>& cam, int n, const T* mean, const T* log_scale, const T* quat,
                            const int* radius, const T* dmean2d, const T* dconic, const T* ddepth, T* dmean,
                            T* dlog_scale, T* dquat);

}  // namespace hgs::render
