// Eqs. 6 and 14 for the J objects of one view. Without boxes (or without the base render): every object over the
// whole image, one object per task. With boxes (the exactness argument is in object_losses.h):
//   1. one pass over the renders (object_boxes.cpp) finds each object's box D_k of pixels that differ from the base
//   render (or
//      carry its label) and copies the base render (and interleaved objects' renders) to planar images;
//   2. tasks: the base pair's eq. 6 and eq. 14 over the image, each small object's terms on its crop Q_k (kept
//      inside R_k), each large object over the whole image; every task cut into bands of rows (each cropped with
//      dep rows above and below) that run as pieces, largest first, each writing its rows' terms and row sums,
//      each one pass down its rows (SSIM's, the band's and eq. 14's rows streamed);
//   3. per object, its sums (rows in order) and the global scalars (means, eq. 14's band total and scale, the
//      projection coefficient) from the base pair's sums outside R_k plus the object's inside it, and its
//      gradient inside R_k completed;
//   4. the gradients back to the interleaved layout: own inside R_k, the base pair's combination outside.
#include "hybrid/object_losses.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>

#include "core/error.h"
#include "hybrid/bro.h"
#include "train/ssim.h"

namespace hgs::hybrid {
namespace {

// Object j's gradient at a value outside its box, from the base pair's there (object_losses.h): g + (gs u - pj p)
// with g = s_app times eq. 6's base gradient, + 0 so that a -0 is stored as +0. The one definition the scatter,
// the sum and gradient_row share, written with fma so that the compiler fuses no product differently in each:
// s_app a rounded on its own (fma(s, a, 0): a -0 read as +0, which the final + 0 makes of it anyway), pj p rounded
// and subtracted from gs u in one fused multiply-add. (These are the roundings the scatter's plain expression
// compiled to before.)
inline float base_app_scaled(float s_app, float a) { return std::fma(s_app, a, 0.f); }
inline float outside_grad(float g, float gs, float u, float pj, float p) {
  return (g + std::fma(gs, u, -(pj * p))) + 0.f;
}

// Eq. 6's gradient of one value: the L1 sign term (a = (1 - lambda) / n, 0 at a tie) plus b = -lambda times
// SSIM's gradient, as train::PhotometricLoss, then times s_app.
inline float app_grad(float d, float a, float b, float gs, float s_app) {
  return ((d > 0 ? a : (d < 0 ? -a : 0.f)) + b * gs) * s_app;
}

}  // namespace

PixelBox PixelBox::grown(int r, int W, int H) const {
  if (empty()) return {};
  return {std::max(0, x0 - r), std::max(0, y0 - r), std::min(W, x1 + r), std::min(H, y1 + r)};
}

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
  for (auto* v : {&pred_, &grad_, &opac_, &base_pred_, &base_app_, &base_unit_, &base_opac_, &planes_})
    std::vector<float>().swap(*v);
  std::vector<double>().swap(base_terms_);
  std::vector<int>().swap(label_obj_);  // (all -1 between calls: find_boxes fills it again when empty)
  std::vector<Object>().swap(obj_);
  grads_ = ObjectGradients{};
}

ObjectRenders ObjectRenders::interleaved(const float* extra, const ObjectLayout& lay) {
  ObjectRenders r;
  for (int j = 0; j < lay.J; ++j) {
    r.color.push_back(extra + lay.color(j));
    r.opacity.push_back(extra + lay.opacity(j));
  }
  if (lay.base) {
    r.base_color = extra + lay.base_color();
    r.base_opacity = extra + lay.base_opacity();
  }
  r.stride = r.base_stride = r.base_opacity_stride = lay.total();
  return r;
}

ObjectRenders ObjectRenders::sparse(const float* dense, int dense_stride, int base_opacity, const float* groups, int J,
                                    long planes) {
  ObjectRenders r;
  const long first = planes > 0 ? 4 * planes : 4;  // from group j to group j + 1
  for (int j = 0; j < J; ++j) {
    r.color.push_back(groups + first * j);
    r.opacity.push_back(groups + first * j + 3);
  }
  r.stride = planes > 0 ? 4L : 4L * J;
  r.base_color = dense;
  r.base_opacity = dense + base_opacity;
  r.base_stride = r.base_opacity_stride = dense_stride;
  r.deltas = true;
  return r;
}

ObjectRenders& ObjectRenders::with_live_tiles(const uint8_t* flags, int tile_size, int width, int height) {
  live = flags;
  tile = tile_size;
  tiles_x = (width + tile_size - 1) / tile_size;
  tiles = long(tiles_x) * ((height + tile_size - 1) / tile_size);
  return *this;
}

ObjectLossValues ObjectLosses::operator()(const Image& image, const LabelMap& lab, const float* extra,
                                          const ObjectLayout& lay, const std::vector<int>& objs, float* d_extra,
                                          float* color_sum) {
  return (*this)(image, lab, ObjectRenders::interleaved(extra, lay), objs,
                 ObjectGradOut{d_extra, lay.total(), color_sum, 3});
}

ObjectLossValues ObjectLosses::operator()(const Image& image, const LabelMap& lab, const ObjectRenders& renders,
                                          const std::vector<int>& objs, const ObjectGradOut& out) {
  if (renders.J() != static_cast<int>(objs.size()))
    throw Error("object losses: " + std::to_string(renders.J()) + " object renders for " + std::to_string(objs.size()) +
                " objects");
  const size_t threads = size_t(std::max(1, omp_get_max_threads()));
  if (scratch_.size() < threads) scratch_.resize(threads, Scratch(cfg_.lambda_dssim));
  width_ = image.width;
  if (renders.base_color && opt_.boxes && !objs.empty()) return box_path(image, lab, renders, objs, out);
  return full_path(image, lab, renders, objs, out);
}

// Object k over the whole image. pred [H, W, 3], opac [H, W] -> grad [H, W, 3] (overwritten) = d(lambda_app app
// + lambda_bro bro) / J; app and bro its eq. 6 and eq. 14 (the latter as optimised, times the scale rule).
void ObjectLosses::score_full(Scratch& w, const Image& image, const LabelMap& lab, int k, int J, const float* pred,
                              const float* opac, float* grad, double& app, double& bro) {
  const int W = image.width, H = image.height;
  const size_t HW = size_t(W) * H;
  w.gt.resize(HW * 3);
  w.mask.resize(HW);
  w.band.resize(HW);
  for (size_t p = 0; p < HW; ++p) {
    const float m = lab.v[p] == k ? 1.f : 0.f;
    w.mask[p] = m;
    for (int c = 0; c < 3; ++c) w.gt[p * 3 + c] = image.px[p * 3 + c] * m;
  }
  train::LossValues lv = w.loss(pred, w.gt.data(), H, W, grad);
  app = lv.total;
  bro = 0;
  const float s_app = cfg_.lambda_app / J;
  for (size_t i = 0; i < HW * 3; ++i) grad[i] *= s_app;
  if (!(cfg_.use_bro && cfg_.lambda_bro > 0)) return;
  // B is built from the rendered opacity but treated as a constant: no gradient through the morphology.
  boundary_band(opac, w.mask.data(), H, W, cfg_.bro_kernel, w.band.data());
  const double band_total = band_weight_total(w.band.data(), H, W);
  const float f = cfg_.bro_image_norm ? float(band_total / (2.0 * HW)) : 1.f;
  const float s_bro = f * cfg_.lambda_bro / J;
  if (!cfg_.bro_scale_invariant) {  // eq. 14's own gradient
    bro = bro_loss(pred, w.gt.data(), 3, 3, w.band.data(), H, W, cfg_.bro_eps, grad, s_bro, band_total);
  } else {  // the same value; its gradient without the component that scales the whole render (bro.h)
    w.bgrad.assign(HW * 3, 0.f);
    bro = bro_loss(pred, w.gt.data(), 3, 3, w.band.data(), H, W, cfg_.bro_eps, w.bgrad.data(), s_bro, band_total);
    remove_scale_component(pred, HW * 3, w.bgrad.data());
    for (size_t i = 0; i < HW * 3; ++i) grad[i] += w.bgrad[i];
  }
  bro *= f;  // the term as optimised
}

ObjectLossValues ObjectLosses::full_path(const Image& image, const LabelMap& lab, const ObjectRenders& renders,
                                         const std::vector<int>& objs, const ObjectGradOut& out) {
  times_ = {};
  const int W = image.width, H = image.height, J = static_cast<int>(objs.size());
  const size_t HW = size_t(W) * H;
  app_.assign(J, 0.0);
  bro_.assign(J, 0.0);
  // Object images to planar [J][H, W, 3] (+ opacities [J][H, W]) in one pass over the interleaved render.
  pred_.resize(size_t(J) * HW * 3);
  grad_.resize(size_t(J) * HW * 3);
  opac_.resize(size_t(J) * HW);
#pragma omp parallel for schedule(static)
  for (long p = 0; p < long(HW); ++p) {
    for (int j = 0; j < J; ++j) {
      const bool in = renders.in_memory(j, int(p % W), int(p / W));
      for (int c = 0; c < 3; ++c) pred_[(size_t(j) * HW + p) * 3 + c] = renders.color_at(j, p, c, in);
      opac_[size_t(j) * HW + p] = renders.opacity_at(j, p, in);
    }
  }
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < J; ++j)
    score_full(scratch_[omp_get_thread_num()], image, lab, objs[j], J, &pred_[size_t(j) * HW * 3],
               &opac_[size_t(j) * HW], &grad_[size_t(j) * HW * 3], app_[j], bro_[j]);
  // Gradients back to the interleaved layout (the colour channels of a pixel are contiguous), and their sum.
  if (out.color || out.sum) {
#pragma omp parallel for schedule(static)
    for (long p = 0; p < long(HW); ++p) {
      float sum[3] = {0.f, 0.f, 0.f};
      for (int j = 0; j < J; ++j)
        for (int c = 0; c < 3; ++c) {
          const float v = grad_[(size_t(j) * HW + p) * 3 + c] + 0.f;  // + 0: a -0 stored as +0 (see scatter)
          if (out.color) out.color[p * out.stride + 3 * j + c] = v;
          sum[c] += v;
        }
      if (out.sum)
        for (int c = 0; c < 3; ++c) out.sum[p * out.sum_stride + c] = sum[c];
    }
  }
  grads_ = ObjectGradients{};
  grads_.app_scale = J ? cfg_.lambda_app / J : 0.f;
  for (int j = 0; j < J; ++j) {
    grads_.box.push_back({0, 0, W, H});
    grads_.own.push_back(&grad_[size_t(j) * HW * 3]);
  }
  grads_.bro_scale.assign(J, 0.f);
  grads_.proj.assign(J, 0.f);
  ObjectLossValues v;
  for (int j = 0; j < J; ++j) {
    v.app += app_[j];
    v.bro += bro_[j];
  }
  if (J) v.app /= J, v.bro /= J;
  return v;
}

// The base pair's eq. 6 over image rows [y0, y1): base_app_ [H, W, 3] its gradient there (without s_app), the L1
// and SSIM-map terms per pixel and their row sums. SSIM's rows streamed (train::ssim_rows_streamed) and used as
// they come.
void ObjectLosses::score_base_app(Scratch& w, int H, int W, int y0, int y1) {
  const size_t L = size_t(W) * 3, HW = size_t(W) * H;
  const double n = double(H) * L;
  const float lam = cfg_.lambda_dssim, a = (1 - lam) / float(n), b = -lam;
  const auto sink = [&](int y, const float* sg, const float* sm) {
    double l1_row = 0, ssim_row = 0;
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * W + x;
      double l1 = 0, ss = 0;
      for (int c = 0; c < 3; ++c) {
        const float d = base_pred_[p * 3 + c] - 0.f;
        l1 += std::abs(d);
        ss += sm[size_t(x) * 3 + c];
        base_app_[p * 3 + c] = app_grad(d, a, b, sg[size_t(x) * 3 + c], 1.f);
      }
      base_terms_[kL1 * HW + p] = l1;
      base_terms_[kSsim * HW + p] = ss;
      l1_row += l1;
      ssim_row += ss;
    }
    base_rows_[size_t(y) * kTerms + kL1] = l1_row;
    base_rows_[size_t(y) * kTerms + kSsim] = ssim_row;
  };
  train::ssim_rows_streamed<float>([&](int r) { return &base_pred_[r * L]; }, {}, H, W, 3, y0, y1, n, w.ssim, sink);
}

// The base pair's eq. 14 over image rows [y0, y1) (band from the base opacity, mask 0): base_unit_ [H, W, 3]
// there, the band weight, numerator and dot-product terms per pixel and their row sums. The band's and eq. 14's
// rows streamed (BandRows, BroRows) from the row above the first (its y pairs reach row y0).
void ObjectLosses::score_base_bro(Scratch& w, int H, int W, int y0, int y1) {
  const size_t L = size_t(W) * 3, HW = size_t(W) * H;
  w.zero.assign(L, 0.f);  // the mask's and the target's rows
  w.urow.resize(L);
  w.wrow.resize(W);
  w.nrow.resize(W);
  w.band_rows.reset(H, W, cfg_.bro_kernel);
  w.bro_rows.reset(W, 3);
  const float* zero = w.zero.data();
  const BandRows::Row A = [&](int r) { return &base_opac_[size_t(r) * W]; }, M = [&](int) { return zero; };
  const int first = std::max(0, y0 - 1);
  const float* band = w.band_rows.row(first, A, M);
  for (int y = first; y < y1; ++y) {
    const bool next = y + 1 < H;
    const float* band_next = next ? w.band_rows.row(y + 1, A, M) : nullptr;
    w.bro_rows.row(&base_pred_[y * L], zero, band, next ? &base_pred_[(y + 1) * L] : nullptr, next ? zero : nullptr,
                   band_next, w.wrow.data(), w.nrow.data(), w.urow.data());
    band = band_next;
    if (y < y0) continue;  // the row above: its y pairs only
    double row[kTerms] = {};
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * W + x;
      double gp = 0, pp = 0;
      for (int c = 0; c < 3; ++c) {
        const float u = w.urow[size_t(x) * 3 + c], pr = base_pred_[p * 3 + c];
        base_unit_[p * 3 + c] = u;
        gp += double(u) * double(pr);
        pp += double(pr) * double(pr);
      }
      const double t[kTerms] = {0, 0, w.wrow[x], w.nrow[x], gp, pp};
      for (int k : {kWsum, kNum, kGp, kPp}) {
        base_terms_[k * HW + p] = t[k];
        row[k] += t[k];
      }
    }
    for (int k : {kWsum, kNum, kGp, kPp}) base_rows_[size_t(y) * kTerms + k] = row[k];
  }
}

// Step 2 for rows [y0, y1) of object j's box R (all of them for a small object, a band of the image for a large
// one): its crop Q = those rows of R grown by dep_, eq. 6 and eq. 14's parts there, kept inside R: own = eq. 6's
// gradient, unit = eq. 14's unscaled gradient, pred the render, rows[] the per-pixel terms summed over each row.
// One pass down the crop: its rows are read from the renders into a ring as the passes first ask for them, SSIM's
// rows (train::ssim_rows_streamed) come out in order, and each R row's eq. 6 terms, band row (BandRows) and eq.
// 14's parts (BroRows) are made as its SSIM row comes; nothing larger than a few rows of the crop is written
// besides R's outputs.
void ObjectLosses::score_crop(Scratch& w, const Image& image, const LabelMap& lab, int j, int k, int y0, int y1) {
  Object& o = obj_[j];
  const int W = image.width, H = image.height, J = static_cast<int>(obj_.size());
  const size_t n = size_t(W) * H * 3;
  const PixelBox R{o.R.x0, y0, o.R.x1, y1};
  const PixelBox Q = R.grown(dep_, W, H);
  const int qw = Q.width(), qh = Q.height(), rw = R.width(), rh = R.height();
  const int rx = R.x0 - Q.x0, ry = R.y0 - Q.y0;  // R inside the crop
  const bool bro_on = cfg_.use_bro && cfg_.lambda_bro > 0;
  const size_t out0 = size_t(y0 - o.R.y0) * rw;  // the band's first pixel in o's arrays
  if (size_t(qw) * qh == 0) return;
  // The crop's rows, each [8 qw]: pred and gt = I * M_k [qw, 3], mask, opac [qw], in a ring of `ring` rows,
  // filled in order as first asked for. With r = s/2, r2 = s - 1 - r: when SSIM hands out row y, rows up to
  // y + 10 are filled; the band of the row above R's first then reads from row ry - 1 - r, and later bands read
  // ahead to y + 1 + r2 while rows y and y + 1 are still to be read. So no row is asked for more than
  // max(11 + r, s + 1) rows before the latest filled, and 16 + s rows hold them. (A row asked for after it left
  // the ring would be a bug: it is flagged, and box_path fails after the pieces. With a ring of max(12 + r,
  // s + 2) rows the box tests pass, with one row less they fail on the flag: the bound is the one reached.)
  const int ring = 16 + cfg_.bro_kernel;
  const size_t rf = size_t(qw) * 8;
  w.crop.resize(size_t(ring) * rf);
  int filled = -1;
  auto fill = [&](int r) {  // the object's values from its plane (renders_: base + difference, or planes_)
    float* d = &w.crop[size_t(r % ring) * rf];
    const int y = r + Q.y0;
    auto columns = [&]<bool kIn>(int xx0, int xx1) {
      for (int xx = xx0; xx < xx1; ++xx) {
        const long p = long(y) * W + (xx + Q.x0);
        const float m = lab.v[p] == k ? 1.f : 0.f;
        d[6 * qw + xx] = m;
        d[7 * qw + xx] = renders_.opacity_at(j, p, kIn);
        for (int c = 0; c < 3; ++c) {
          d[xx * 3 + c] = renders_.color_at(j, p, c, kIn);
          d[3 * qw + xx * 3 + c] = image.px[p * 3 + c] * m;
        }
      }
    };
    for (int xx0 = 0; xx0 < qw;) {  // runs of columns whose values are in memory or +0 alike
      const int xx1 = renders_.run_end(xx0 + Q.x0, Q.x1) - Q.x0;
      if (renders_.in_memory(j, xx0 + Q.x0, y)) columns.template operator()<true>(xx0, xx1);
      else columns.template operator()<false>(xx0, xx1);
      xx0 = xx1;
    }
  };
  bool overrun = false;  // (a local: the thread's Scratch is written once, at the end)
  auto at = [&](int r) {
    for (; filled < r; ++filled) fill(filled + 1);
    overrun |= r <= filled - ring;
    return &w.crop[size_t(r % ring) * rf];
  };
  // Eq. 14's rows (the band from the object's opacity and mask) from the row above R's first (its y pairs).
  w.urow.resize(size_t(qw) * 3);
  w.wrow.resize(qw);
  w.nrow.resize(qw);
  const BandRows::Row opac = [&](int r) { return at(r) + 7 * qw; }, mask = [&](int r) { return at(r) + 6 * qw; };
  const float* band = nullptr;
  auto bro_row = [&](int y) {  // band row y in `band` before, row y + 1 after
    const bool next = y + 1 < qh;
    const float* band_next = next ? w.band_rows.row(y + 1, opac, mask) : nullptr;
    const float* pr = at(y);
    const float* pn = next ? at(y + 1) : nullptr;
    w.bro_rows.row(pr, pr + 3 * qw, band, pn, next ? pn + 3 * qw : nullptr, band_next, w.wrow.data(), w.nrow.data(),
                   w.urow.data());
    band = band_next;
  };
  const float lam = cfg_.lambda_dssim, a = (1 - lam) / float(n), b = -lam, s_app = cfg_.lambda_app / J;
  const auto sink = [&](int yy, const float* sg, const float* sm) {
    const float* cr = at(yy);
    const size_t i0 = size_t(rx) * 3;
    const float *pr = cr + i0, *gt = cr + 3 * qw + i0;
    sg += i0, sm += i0;
    float* own = &o.own[(out0 + size_t(yy - ry) * rw) * 3];
    double l1 = 0, ss = 0;
#pragma omp simd reduction(+ : l1, ss)
    for (int i = 0; i < rw * 3; ++i) {
      const float d = pr[i] - gt[i];
      l1 += std::abs(d);
      ss += sm[i];
      own[i] = app_grad(d, a, b, sg[i], s_app);
    }
    double* row = &o.rows[(size_t(y0 - o.R.y0) + (yy - ry)) * kTerms];
    row[kL1] = l1;
    row[kSsim] = ss;
    if (!bro_on) return;
    if (yy == ry) {
      w.band_rows.reset(qh, qw, cfg_.bro_kernel);
      w.bro_rows.reset(qw, 3);
      band = w.band_rows.row(std::max(0, ry - 1), opac, mask);
      if (ry > 0) bro_row(ry - 1);
    }
    bro_row(yy);
    double ws = 0, num = 0, gp = 0, pp = 0;
    for (int xx = 0; xx < rw; ++xx) {
      ws += w.wrow[rx + xx];
      num += w.nrow[rx + xx];
    }
    const float* u = &w.urow[i0];
#pragma omp simd reduction(+ : gp, pp)
    for (int i = 0; i < rw * 3; ++i) {
      gp += double(u[i]) * double(pr[i]);
      pp += double(pr[i]) * double(pr[i]);
    }
    std::copy_n(u, rw * 3, &o.unit[(out0 + size_t(yy - ry) * rw) * 3]);
    if (!o.pred.empty()) std::copy_n(pr, rw * 3, &o.pred[(out0 + size_t(yy - ry) * rw) * 3]);
    row[kWsum] = ws;
    row[kNum] = num;
    row[kGp] = gp;
    row[kPp] = pp;
  };
  // Eq. 6: SSIM on the crop with the image's normaliser (the target is 0 outside the mask's box: y's passes run
  // there only), R's columns.
  const train::SsimSupport ys{o.M.x0 - Q.x0, o.M.y0 - Q.y0, o.M.x1 - Q.x0, o.M.y1 - Q.y0};
  train::ssim_rows_streamed<float>([&](int r) { return at(r); }, [&](int r) { return at(r) + 3 * qw; }, qh, qw, 3, ry,
                                   ry + rh, double(n), w.ssim, sink, o.M.empty() ? train::SsimSupport{0, 0, 0, 0} : ys,
                                   rx, rx + rw);
  w.ring_overrun |= overrun;
}

// Terms [kT0, kT1) of the base pair summed over box r into out [kTerms], each one running sum in raster order
// (the planes of those terms alone are read; the terms' sums are independent chains: one term per task left each
// task waiting on its adder, 1.6x the time of all six together).
template <int kT0, int kT1>
void ObjectLosses::base_sums(const PixelBox& r, int W, int H, double* out) const {
  const size_t HW = size_t(W) * H;
  double s[kT1 - kT0] = {};
  for (int y = r.y0; y < r.y1 && !r.empty(); ++y)
    for (int x = r.x0; x < r.x1; ++x) {
      const size_t p = size_t(y) * W + x;
      for (int t = kT0; t < kT1; ++t) s[t - kT0] += base_terms_[t * HW + p];
    }
  for (int t = kT0; t < kT1; ++t) out[t] = s[t - kT0];
}

// Step 3 for an object: its sums over R (its rows in order), its values (into app_[j], bro_[j]) and scalars
// from the base pair's sums outside R (o.base_in, from base_sums) plus its own inside (a full object: its own alone).
// complete_rows then adds eq. 14's part to its gradient inside R.
void ObjectLosses::finish_box(int W, int H, int j) {
  Object& o = obj_[j];
  const size_t HW = size_t(W) * H;
  const double n = double(HW) * 3;
  const int J = static_cast<int>(obj_.size());
  double in[kTerms] = {};  // its terms summed over R, the rows in order
  for (size_t r = 0; r < o.rows.size(); r += kTerms)
    for (int t = 0; t < kTerms; ++t) in[t] += o.rows[r + t];
  auto whole = [&](int t) {  // the object's sum over the image
    return o.full ? in[t] : base_total_[t] - o.base_in[t] + in[t];
  };
  const float lam = cfg_.lambda_dssim;
  const float l1 = float(whole(kL1) / n), ss = float(whole(kSsim) / n);
  app_[j] = (1 - lam) * l1 + lam * (1 - ss);
  bro_[j] = 0;
  o.bro_scale = o.proj = 0;
  if (!(cfg_.use_bro && cfg_.lambda_bro > 0)) return;
  const double band_total = whole(kWsum);
  const float f = cfg_.bro_image_norm ? float(band_total / (2.0 * HW)) : 1.f;
  const float s_bro = f * cfg_.lambda_bro / J;
  const float den = float(3 * band_total) + cfg_.bro_eps;
  const float gs = s_bro / den;
  bro_[j] = double(float(whole(kNum)) / den) * f;
  o.bro_scale = gs;
  if (cfg_.bro_scale_invariant) {
    // remove_scale_component's dot products <g, p>, <p, p> over the image. A non-finite ratio can only come from
    // cancellation where p is 0 everywhere, when the projection removes nothing.
    const double pp = whole(kPp);
    const float proj = pp > 0 ? float(double(gs) * whole(kGp) / pp) : 0.f;
    o.proj = std::isfinite(proj) ? proj : 0.f;
  }
}

// Eq. 14's part of object j's gradient inside R, rows [r0, r1) of R: own += s u (- a p with the projection).
// Element by element, so that any cut into rows gives the same bits. (A no-op without eq. 14: unit is empty.)
void ObjectLosses::complete_rows(int j, int r0, int r1) {
  Object& o = obj_[j];
  if (o.unit.empty()) return;
  const float gsf = o.bro_scale, a = o.proj;
  const size_t w3 = size_t(o.R.width()) * 3, i0 = size_t(r0) * w3, i1 = size_t(r1) * w3;
  if (o.pred.empty()) {
    for (size_t i = i0; i < i1; ++i) o.own[i] += gsf * o.unit[i];
  } else {
    for (size_t i = i0; i < i1; ++i) o.own[i] += gsf * o.unit[i] - a * o.pred[i];
  }
}

// Step 4: out.color = each object's gradient: own inside R, the base pair's combination outside; and out.sum
// their sum over the objects (ObjectGradOut). Pixel by pixel: the base pair's values are loaded once for the
// J colour triples of the pixel. (Each value is stored + 0, so a -0 is stored as +0: the bits of the sum into a
// zeroed buffer this replaced.)
void ObjectLosses::scatter(int H, int W, bool bro_grad, const ObjectGradOut& out) const {
  const int J = static_cast<int>(obj_.size());
  const float s_app = grads_.app_scale;
  const bool has_base = !base_app_.empty();  // else every object is scored over the whole image
  const std::vector<float>&gs = grads_.bro_scale, &proj = grads_.proj;
  // Compiled for each case of the base pair (with eq. 14's terms, without them, not scored).
  auto run = [&]<bool kBase, bool kBro>() {
#pragma omp parallel
    {
      std::vector<int> xa(J), xb(J);
      std::vector<const float*> own(J);
#pragma omp for schedule(static)
      for (int y = 0; y < H; ++y) {
        for (int j = 0; j < J; ++j) {  // object j's own columns [xa, xb) in this row; own[j] at column xa
          const PixelBox& R = obj_[j].R;
          const bool in_rows = y >= R.y0 && y < R.y1;
          xa[j] = in_rows ? R.x0 : W;
          xb[j] = in_rows ? R.x1 : W;
          own[j] = in_rows ? obj_[j].own.data() + size_t(y - R.y0) * R.width() * 3 : nullptr;
        }
        for (int x = 0; x < W; ++x) {
          float* const px = out.color ? out.color + (long(y) * W + x) * out.stride : nullptr;
          const size_t i = (size_t(y) * W + x) * 3;
          float g[3] = {}, u[3] = {}, p[3] = {}, sum[3] = {0.f, 0.f, 0.f};
          if constexpr (kBase)
            for (int c = 0; c < 3; ++c) {
              g[c] = base_app_scaled(s_app, base_app_[i + c]);
              u[c] = kBro ? base_unit_[i + c] : 0.f;
              p[c] = base_pred_[i + c];
            }
          for (int j = 0; j < J; ++j) {
            float v[3];
            if (x >= xa[j] && x < xb[j]) {
              const float* o = own[j] + size_t(x - xa[j]) * 3;
              for (int c = 0; c < 3; ++c) v[c] = o[c] + 0.f;
            } else if constexpr (kBro) {
              for (int c = 0; c < 3; ++c) v[c] = outside_grad(g[c], gs[j], u[c], proj[j], p[c]);
            } else {
              for (int c = 0; c < 3; ++c) v[c] = g[c] + 0.f;
            }
            if (px)
              for (int c = 0; c < 3; ++c) px[3 * j + c] = v[c];
            for (int c = 0; c < 3; ++c) sum[c] += v[c];
          }
          if (out.sum)
            for (int c = 0; c < 3; ++c) out.sum[(long(y) * W + x) * out.sum_stride + c] = sum[c];
        }
      }
    }
  };
  // The sum alone (the renderer reads each object's values on demand, gradient_row): row by row, each object's
  // row added to the row's sums in object order (each pixel's additions as above), as runs of contiguous values
  // the compiler vectorises.
  auto sum_rows = [&]<bool kBase, bool kBro>() {
#pragma omp parallel
    {
      std::vector<float> g(size_t(W) * 3), acc(size_t(W) * 3);
#pragma omp for schedule(static)
      for (int y = 0; y < H; ++y) {
        const size_t r0 = size_t(y) * W * 3;
        if constexpr (kBase)
          for (int i = 0; i < 3 * W; ++i) g[i] = base_app_scaled(s_app, base_app_[r0 + i]);
        std::fill(acc.begin(), acc.end(), 0.f);
        for (int j = 0; j < J; ++j) {
          const PixelBox& R = obj_[j].R;
          const bool in_rows = y >= R.y0 && y < R.y1;
          const int a = in_rows ? 3 * R.x0 : 3 * W, b = in_rows ? 3 * R.x1 : 3 * W;
          if (in_rows) {
            const float* o = obj_[j].own.data() + size_t(y - R.y0) * R.width() * 3;
#pragma omp simd
            for (int i = a; i < b; ++i) acc[i] += o[i - a] + 0.f;
          }
          if constexpr (kBase) {
            const float gj = gs[j], pj = proj[j];
            auto outside = [&](int i0, int i1) {
              if constexpr (kBro) {
                const float *u = &base_unit_[r0], *p = &base_pred_[r0];
#pragma omp simd
                for (int i = i0; i < i1; ++i) acc[i] += outside_grad(g[i], gj, u[i], pj, p[i]);
              } else {
#pragma omp simd
                for (int i = i0; i < i1; ++i) acc[i] += g[i] + 0.f;
              }
            };
            outside(0, a);
            outside(b, 3 * W);
          }
        }
        for (int x = 0; x < W; ++x)
          for (int c = 0; c < 3; ++c) out.sum[(long(y) * W + x) * out.sum_stride + c] = acc[size_t(x) * 3 + c];
      }
    }
  };
  if (!out.color && has_base) {
    if (bro_grad) sum_rows.template operator()<true, true>();
    else sum_rows.template operator()<true, false>();
    return;
  }
  if (!has_base) run.template operator()<false, false>();
  else if (bro_grad) run.template operator()<true, true>();
  else run.template operator()<true, false>();
}

void ObjectLosses::gradient_row(int j, int y, int x0, int n, float* out) const {
  const PixelBox& R = grads_.box[j];
  const bool rows = y >= R.y0 && y < R.y1;
  const float s_app = grads_.app_scale, gs = grads_.bro_scale[j], pj = grads_.proj[j];
  for (int l = 0; l < n; ++l) {
    const int x = x0 + l;
    float* o = out + 3 * l;
    if (rows && x >= R.x0 && x < R.x1) {  // its own
      const float* v = grads_.own[j] + (size_t(y - R.y0) * R.width() + (x - R.x0)) * 3;
      for (int c = 0; c < 3; ++c) o[c] = v[c] + 0.f;
      continue;
    }
    if (!grads_.base_app) {  // (every box is the whole image then)
      for (int c = 0; c < 3; ++c) o[c] = 0.f;
      continue;
    }
    const size_t i = (size_t(y) * width_ + x) * 3;
    for (int c = 0; c < 3; ++c) {
      const float g = base_app_scaled(s_app, grads_.base_app[i + c]);
      o[c] = grads_.base_unit ? outside_grad(g, gs, grads_.base_unit[i + c], pj, grads_.base_pred[i + c]) : g + 0.f;
    }
  }
}

ObjectLossValues ObjectLosses::box_path(const Image& image, const LabelMap& lab, const ObjectRenders& renders,
                                        const std::vector<int>& objs, const ObjectGradOut& out) {
  const int W = image.width, H = image.height, J = static_cast<int>(objs.size());
  const size_t HW = size_t(W) * H;
  const bool bro_on = cfg_.use_bro && cfg_.lambda_bro > 0;
  using Clock = std::chrono::steady_clock;
  auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  const auto t0 = Clock::now();
  app_.assign(J, 0.0);
  bro_.assign(J, 0.0);
  find_boxes(lab, renders, objs);
  const auto t1 = Clock::now();
  bool any_box = false;
  for (const Object& o : obj_) any_box |= !o.full;
  if (any_box) {
    base_terms_.resize(HW * kTerms);
    base_rows_.assign(size_t(H) * kTerms, 0.0);
    base_app_.resize(HW * 3);
    if (bro_on) base_unit_.resize(HW * 3);
  } else {
    base_app_.clear();  // scatter reads the base pair only when it was scored for this view (any size)
  }
  for (Object& o : obj_) {  // the outputs the pieces fill, row by row
    const size_t n = o.R.area() * 3;
    resize_discarding(o.own, n);  // (every value written by the pieces: the last view's need not be kept)
    resize_discarding(o.unit, bro_on ? n : 0);
    resize_discarding(o.pred, bro_on && cfg_.bro_scale_invariant ? n : 0);
    o.rows.assign(size_t(o.R.height()) * kTerms, 0.0);
  }
  // Step 2: tasks (-1: the base pair's eq. 6, -2: its eq. 14, j: object j) over rows [y0, y1), cut into bands.
  struct Piece {
    double cost;
    int id, y0, y1;
  };
  const double bro_cost = bro_on ? 0.5 : 0.0;
  std::vector<Piece> tasks;
  if (any_box) tasks.push_back({double(HW), -1, 0, H});
  if (any_box && bro_on) tasks.push_back({bro_cost * double(HW), -2, 0, H});
  for (int j = 0; j < J; ++j)
    if (!obj_[j].R.empty()) tasks.push_back({(1 + bro_cost) * double(obj_[j].Q.area()), j, obj_[j].R.y0, obj_[j].R.y1});
  const int threads = std::max(1, omp_get_max_threads());
  double total = 0;
  for (const Piece& t : tasks) total += t.cost;
  // Bands: at most a quarter of a thread's share each, at least kMinBandRows rows (the crop adds 2 dep_ rows).
  constexpr int kMinBandRows = 24;
  std::vector<Piece> pieces;
  for (const Piece& t : tasks) {
    const int rows = t.y1 - t.y0;
    int bands = 1;
    if (opt_.band_rows > 0) bands = (rows + opt_.band_rows - 1) / opt_.band_rows;
    else if (threads > 1)
      bands = std::clamp(int(std::ceil(t.cost / (total / (4.0 * threads)))), 1, std::max(1, rows / kMinBandRows));
    for (int b = 0; b < bands; ++b) {
      const int y0 = t.y0 + int(long(rows) * b / bands), y1 = t.y0 + int(long(rows) * (b + 1) / bands);
      pieces.push_back({t.cost * (y1 - y0 + 2 * dep_) / double(rows + 2 * dep_), t.id, y0, y1});
    }
  }
  std::stable_sort(pieces.begin(), pieces.end(), [](const Piece& a, const Piece& b) { return a.cost > b.cost; });
  for (Scratch& w : scratch_) w.ring_overrun = false;
#pragma omp parallel for schedule(dynamic, 1)
  for (int t = 0; t < int(pieces.size()); ++t) {
    Scratch& w = scratch_[omp_get_thread_num()];
    const Piece& pc = pieces[t];
    if (pc.id == -1) score_base_app(w, H, W, pc.y0, pc.y1);
    else if (pc.id == -2) score_base_bro(w, H, W, pc.y0, pc.y1);
    else score_crop(w, image, lab, pc.id, objs[pc.id], pc.y0, pc.y1);
  }
  for (const Scratch& w : scratch_)
    if (w.ring_overrun) throw Error("object losses: internal error: a crop row was read after it left the ring");
  const auto t2 = Clock::now();
  if (any_box)  // the base pair's totals, its rows in order
    for (int t = 0; t < kTerms; ++t) {
      base_total_[t] = 0;
      for (int y = 0; y < H; ++y) base_total_[t] += base_rows_[size_t(y) * kTerms + t];
    }
  // Step 3: the base pair's terms over each box (one task per object for eq. 6's two terms and one for eq.
  // 14's four, each term one running sum in a fixed order), each object's scalars (one task per object), then
  // eq. 14's part of its gradient, cut into bands of its rows so that a large object is no single task (a full
  // object's own gradient is then complete over the image: nothing of the base pair outside).
  std::vector<std::array<int, 2>> sums;  // (object, 0: eq. 6's terms / 1: eq. 14's)
  for (int j = 0; j < J; ++j) {
    std::fill(obj_[j].base_in, obj_[j].base_in + kTerms, 0.0);
    if (obj_[j].full || obj_[j].R.empty()) continue;
    sums.push_back({j, 0});
    if (bro_on) sums.push_back({j, 1});
  }
  std::stable_sort(sums.begin(), sums.end(), [&](const auto& a, const auto& b) {  // the largest boxes first
    return obj_[a[0]].R.area() > obj_[b[0]].R.area();
  });
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t i = 0; i < sums.size(); ++i) {
    const auto [j, g] = sums[i];
    if (g == 0) base_sums<kL1, kWsum>(obj_[j].R, W, H, obj_[j].base_in);
    else base_sums<kWsum, kTerms>(obj_[j].R, W, H, obj_[j].base_in);
  }
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < J; ++j) finish_box(W, H, j);
  constexpr int kCompleteRows = 32;
  std::vector<std::array<int, 3>> bands;  // (object, first row of R, end row)
  for (int j = 0; j < J; ++j)
    for (int r = 0; r < obj_[j].R.height(); r += kCompleteRows)
      bands.push_back({j, r, std::min(obj_[j].R.height(), r + kCompleteRows)});
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t b = 0; b < bands.size(); ++b) complete_rows(bands[b][0], bands[b][1], bands[b][2]);
  for (Object& o : obj_)
    if (o.full) o.bro_scale = o.proj = 0;
  const auto t3 = Clock::now();
  grads_ = ObjectGradients{};
  grads_.app_scale = cfg_.lambda_app / J;
  for (const Object& o : obj_) {
    grads_.box.push_back(o.R);
    grads_.own.push_back(o.own.data());
    grads_.bro_scale.push_back(o.bro_scale);
    grads_.proj.push_back(o.proj);
  }
  if (any_box) {
    grads_.base_app = base_app_.data();
    grads_.base_pred = base_pred_.data();
    if (bro_on) grads_.base_unit = base_unit_.data();
  }
  if (out.color || out.sum) scatter(H, W, any_box && bro_on, out);
  const int finish_tasks = int(sums.size()) + J + int(bands.size());
  times_ = {ms(t0, t1), ms(t1, t2), ms(t2, t3), ms(t3, Clock::now()), int(pieces.size()), finish_tasks};
  ObjectLossValues v;
  for (int j = 0; j < J; ++j) {
    v.app += app_[j];
    v.bro += bro_[j];
  }
  v.app /= J, v.bro /= J;
  return v;
}

}  // namespace hgs::hybrid
