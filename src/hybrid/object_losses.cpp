#include "hybrid/object_losses.h"

#include <omp.h>

#include <algorithm>

#include "hybrid/bro.h"

namespace hgs::hybrid {

std::vector<int> sample_objects(const std::vector<int>& present, int m, std::mt19937_64& rng) {
  const int J = static_cast<int>(present.size());
  if (m <= 0 || m >= J) return present;
  std::vector<int> idx(J);
  for (int j = 0; j < J; ++j) idx[j] = j;
  for (int j = 0; j < m; ++j) {
    std::uniform_int_distribution<int> pick(j, J - 1);
    std::swap(idx[j], idx[pick(rng)]);
  }
  idx.resize(m);
  std::sort(idx.begin(), idx.end());
  std::vector<int> out(m);
  for (int j = 0; j < m; ++j) out[j] = present[idx[j]];
  return out;
}

void ObjectLosses::release() {
  for (auto* v : {&pred_, &grad_, &opac_}) std::vector<float>().swap(*v);
}

ObjectLossValues ObjectLosses::operator()(const Image& image, const LabelMap& lab, const float* extra,
                                          const ObjectLayout& lay, const std::vector<int>& objs, float* d_extra) {
  const int W = image.width, H = image.height, J = static_cast<int>(objs.size()), C = lay.total();
  const size_t HW = size_t(W) * H;
  const bool bro_on = cfg_.use_bro && cfg_.lambda_bro > 0;
  app_.assign(J, 0.0);
  bro_.assign(J, 0.0);
  // Object images to planar [J][H, W, 3] (+ opacities [J][H, W]) in one pass over the interleaved render.
  pred_.resize(size_t(J) * HW * 3);
  grad_.resize(size_t(J) * HW * 3);
  opac_.resize(size_t(J) * HW);
#pragma omp parallel for schedule(static)
  for (long p = 0; p < long(HW); ++p) {
    const float* e = &extra[size_t(p) * C];
    for (int j = 0; j < J; ++j) {
      for (int c = 0; c < 3; ++c) pred_[(size_t(j) * HW + p) * 3 + c] = e[lay.color(j) + c];
      opac_[size_t(j) * HW + p] = e[lay.opacity(j)];
    }
  }
  const size_t threads = size_t(std::max(1, omp_get_max_threads()));
  if (scratch_.size() < threads) scratch_.resize(threads, Scratch(cfg_.lambda_dssim));
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < J; ++j) {
    Scratch& w = scratch_[omp_get_thread_num()];
    w.gt.resize(HW * 3);
    w.mask.resize(HW);
    w.band.resize(HW);
    const float* pred = &pred_[size_t(j) * HW * 3];
    float* grad = &grad_[size_t(j) * HW * 3];
    const int k = objs[j];
    for (size_t p = 0; p < HW; ++p) {
      const float m = lab.v[p] == k ? 1.f : 0.f;
      w.mask[p] = m;
      for (int c = 0; c < 3; ++c) w.gt[p * 3 + c] = image.px[p * 3 + c] * m;
    }
    train::LossValues lv = w.loss(pred, w.gt.data(), H, W, grad);
    app_[j] = lv.total;
    const float s_app = cfg_.lambda_app / J;
    for (size_t i = 0; i < HW * 3; ++i) grad[i] *= s_app;
    if (bro_on) {
      // B is built from the rendered opacity but treated as a constant: no gradient through the morphology.
      boundary_band(&opac_[size_t(j) * HW], w.mask.data(), H, W, cfg_.bro_kernel, w.band.data(), w.morph);
      const double band_total = band_weight_total(w.band.data(), H, W);
      const float f = cfg_.bro_image_norm ? float(band_total / (2.0 * HW)) : 1.f;
      const float s_bro = f * cfg_.lambda_bro / J;
      if (!cfg_.bro_scale_invariant) {  // eq. 14's own gradient
        bro_[j] = bro_loss(pred, w.gt.data(), 3, 3, w.band.data(), H, W, cfg_.bro_eps, grad, s_bro, band_total);
      } else {  // the same value; its gradient without the component that scales the whole render (bro.h)
        w.bgrad.assign(HW * 3, 0.f);
        bro_[j] =
            bro_loss(pred, w.gt.data(), 3, 3, w.band.data(), H, W, cfg_.bro_eps, w.bgrad.data(), s_bro, band_total);
        remove_scale_component(pred, HW * 3, w.bgrad.data());
        for (size_t i = 0; i < HW * 3; ++i) grad[i] += w.bgrad[i];
      }
      bro_[j] *= f;  // the term as optimised
    }
  }
  // Gradients back to the interleaved layout (the colour channels of a pixel are contiguous).
#pragma omp parallel for schedule(static)
  for (long p = 0; p < long(HW); ++p) {
    float* d = &d_extra[size_t(p) * C];
    for (int j = 0; j < J; ++j)
      for (int c = 0; c < 3; ++c) d[lay.color(j) + c] += grad_[(size_t(j) * HW + p) * 3 + c];
  }
  ObjectLossValues v;
  for (int j = 0; j < J; ++j) {
    v.app += app_[j];
    v.bro += bro_[j];
  }
  if (J) v.app /= J, v.bro /= J;
  return v;
}

}  // namespace hgs::hybrid
