// Step 1 of the object losses' box path (object_losses.h has the exactness argument): each object's box D_k of
// the pixels where its colour or opacity differs bitwise from the base render's or its label is k, the box of its
// label's pixels, R_k = D_k grown by dep and the crop Q_k = R_k grown by dep again; the base render copied to
// planar images on the way. Row by row (rows on the threads):
//   1. the base render's row copied out; where the renderer left objects' planes unwritten (ObjectRenders::live),
//      the first and last pixel of each run of columns (a tile's) whose "+0" object value differs from the base;
//   2. the label's columns: one lookup per pixel (label -> the objects with it), not one test per object;
//   3. per object, its first and last differing column, scanned in from the row's two ends: a scan stops at its
//      first hit and steps over a run the object did not write in one test, so an object present near the ends
//      costs a few pixels and one absent from the row a test per run plus its written tiles (the pass tested
//      every object at every pixel before: a tenth of the 320x240 step's object losses). Where no tile is flagged
//      the row is tested pixel by pixel, every object at each (its streams read once, in order: faster there than
//      object by object); interleaved objects are also copied to their planes in that pass (planes_ [J, H, W, 4],
//      so that the crops read contiguous rows).
// The boxes are the hull of the rows' [first, last] ranges (min / max of the same columns the pixel-by-pixel pass
// took, so the same boxes).
#include <omp.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <utility>

#include "hybrid/object_losses.h"

namespace hgs::hybrid {
namespace {

constexpr int kSsimRadius = 5;  // the SSIM window is 11 x 11

// dep of object_losses.h: the SSIM gradient reads radius 10, eq. 14's differences its band's radius plus one.
int dependency_radius(const HybridConfig& cfg) { return std::max(2 * kSsimRadius, cfg.bro_kernel / 2 + 1); }

inline uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

// A run of columns [x0, x1) whose objects' values are all in memory or all +0 (one tile's columns, or the row),
// and the first and last of its pixels whose +0 value differs from the base (-1: none).
struct ColumnRun {
  int x0, x1, first0, last0;
};

}  // namespace

// Labels [H, W]; renders the J objects' renders; objs [J] their labels.
void ObjectLosses::find_boxes(const LabelMap& lab, const ObjectRenders& renders, const std::vector<int>& objs) {
  const int W = lab.width, H = lab.height, J = static_cast<int>(objs.size());
  const size_t HW = size_t(W) * H;
  const long BS = renders.base_stride, BO = renders.base_opacity_stride, S = renders.stride;
  row_lo_.resize(size_t(J) * H);
  row_hi_.resize(size_t(J) * H);
  mask_lo_.resize(size_t(J) * H);
  mask_hi_.resize(size_t(J) * H);
  base_pred_.resize(HW * 3);
  base_opac_.resize(HW);
  const bool copied = renders.stride != 4;  // (stride 4: each object's pixels are contiguous already)
  if (copied) planes_.resize(size_t(J) * HW * 4);
  else std::vector<float>().swap(planes_);
  std::vector<ScratchVector<ColumnRun>> run_rows(size_t(std::max(1, omp_get_max_threads())));
  std::vector<ScratchVector<uint8_t>> in_rows(run_rows.size());
  // label -> its objects: label_obj_[label] the first, obj_next_[j] the next with the same label (-1: none). Set
  // after every allocation above, and reset to all -1 below the scan, which throws nothing.
  if (label_obj_.empty()) label_obj_.assign(size_t(UINT16_MAX) + 1, -1);
  obj_next_.assign(J, -1);
  auto label_of = [&](int j) { return objs[j] >= 0 && objs[j] <= UINT16_MAX ? objs[j] : -1; };
  for (int j = J - 1; j >= 0; --j)
    if (label_of(j) >= 0) obj_next_[j] = std::exchange(label_obj_[label_of(j)], j);
  // The scan, compiled for each kind of render (complete values or base + difference) and for the copy or none.
  auto scan = [&]<bool kDeltas, bool kCopy>() {
#pragma omp parallel for schedule(static)
    for (int y = 0; y < H; ++y) {
      const long p0 = long(y) * W;
      float* bp = &base_pred_[size_t(p0) * 3];  // [W, 3] this row of the base render
      float* bo = &base_opac_[size_t(p0)];      // [W]
      for (int x = 0; x < W; ++x) {
        for (int c = 0; c < 3; ++c) bp[3 * x + c] = renders.base_color[(p0 + x) * BS + c];
        bo[x] = renders.base_opacity[(p0 + x) * BO];
      }
      // The base's colour and opacity at x, in registers (b [4]).
      auto base = [&](int x, float* b) {
        for (int c = 0; c < 3; ++c) b[c] = bp[3 * x + c];
        b[3] = bo[x];
      };
      // An object's value v [4] where the base is b: from memory (col [3] and o its stored colour and opacity), or
      // +0 where unwritten; and whether it differs from the base.
      auto value = [&](const float* b, const float* col, float o, float* v) {
        for (int c = 0; c < 3; ++c) v[c] = kDeltas ? b[c] + col[c] : col[c];
        v[3] = kDeltas ? b[3] + o : o;
      };
      auto differs = [&](const float* b, const float* v) {
        uint32_t d = 0;
        for (int c = 0; c < 4; ++c) d |= bits(v[c]) ^ bits(b[c]);
        return d != 0;
      };
      static constexpr float kZero[3] = {0.f, 0.f, 0.f};
      // 1. The runs of columns, and where an unwritten (+0) value differs from the base.
      ScratchVector<ColumnRun>& runs = run_rows[omp_get_thread_num()];
      ScratchVector<uint8_t>& in = in_rows[omp_get_thread_num()];  // [J] whether each object's run is in memory
      in.resize(J);
      runs.resize(0);
      for (int x0 = 0; x0 < W;) {
        ColumnRun r{x0, renders.run_end(x0, W), -1, -1};
        if (renders.live)
          for (int x = r.x0; x < r.x1; ++x) {
            float b[4], v[4];
            base(x, b);
            value(b, kZero, 0.f, v);
            if (differs(b, v)) r.first0 = r.first0 < 0 ? x : r.first0, r.last0 = x;
          }
        runs.push_back(r);
        x0 = r.x1;
      }
      // 2. The label's columns.
      int* mlo = &mask_lo_[size_t(y)];
      int* mhi = &mask_hi_[size_t(y)];
      for (int j = 0; j < J; ++j) mlo[size_t(j) * H] = W, mhi[size_t(j) * H] = -1;
      const uint16_t* lrow = &lab.v[size_t(p0)];
      for (int x = 0; x < W; ++x)
        for (int j = label_obj_[lrow[x]]; j >= 0; j = obj_next_[j]) {
          mlo[size_t(j) * H] = std::min(mlo[size_t(j) * H], x);
          mhi[size_t(j) * H] = x;
        }
      // 3. Each object's first and last differing column.
      int* lo = &row_lo_[size_t(y)];
      int* hi = &row_hi_[size_t(y)];
      for (int j = 0; j < J; ++j) lo[size_t(j) * H] = W, hi[size_t(j) * H] = -1;
      if (kCopy || !renders.live) {  // pixel by pixel, every object (interleaved values read once, in order)
        for (const ColumnRun& r : runs) {
          for (int j = 0; j < J; ++j) in[j] = renders.in_memory(j, r.x0, y);
          for (int x = r.x0; x < r.x1; ++x) {
            float b[4];
            base(x, b);
            for (int j = 0; j < J; ++j) {
              float v[4];
              if (in[j]) value(b, renders.color[j] + (p0 + x) * S, renders.opacity[j][(p0 + x) * S], v);
              else value(b, kZero, 0.f, v);
              if constexpr (kCopy) std::copy_n(v, 4, &planes_[(size_t(j) * HW + size_t(p0 + x)) * 4]);
              if (differs(b, v)) lo[size_t(j) * H] = std::min(lo[size_t(j) * H], x), hi[size_t(j) * H] = x;
            }
          }
        }
      } else {  // scanned in from the row's ends (written tiles flagged: most runs skipped in one test)
        for (int j = 0; j < J; ++j) {
          const float* colj = renders.color[j];
          const float* opj = renders.opacity[j];
          // One run from the end of `dir` (+1 from the left, -1 from the right): the first differing column met.
          auto scan_run = [&](const ColumnRun& r, int dir) {
            if (!renders.in_memory(j, r.x0, y)) return dir > 0 ? r.first0 : r.last0;
            for (int x = dir > 0 ? r.x0 : r.x1 - 1; x >= r.x0 && x < r.x1; x += dir) {
              float b[4], v[4];
              base(x, b);
              value(b, colj + (p0 + x) * S, opj[(p0 + x) * S], v);
              if (differs(b, v)) return x;
            }
            return -1;
          };
          int first = W, last = -1;
          for (size_t i = 0; i < runs.size() && first == W; ++i)
            if (const int x = scan_run(runs[i], 1); x >= 0) first = x;
          for (size_t i = runs.size(); i-- > 0 && first < W && last < 0;) last = scan_run(runs[i], -1);
          lo[size_t(j) * H] = first, hi[size_t(j) * H] = last;
          // The next row's scans most likely start at these columns (or the row's ends), a plane's row (W
          // pixels) further on: ask for those lines now, so that their fetch overlaps this row's work.
          if (y + 1 < H) {
            __builtin_prefetch(colj + (p0 + W + (first < W ? first : 0)) * S);
            __builtin_prefetch(colj + (p0 + W + (last >= 0 ? last : W - 1)) * S);
          }
        }
      }
      for (int j = 0; j < J; ++j) {  // and the label's columns
        lo[size_t(j) * H] = std::min(lo[size_t(j) * H], mlo[size_t(j) * H]);
        hi[size_t(j) * H] = std::max(hi[size_t(j) * H], mhi[size_t(j) * H]);
      }
    }
  };
  if (renders.deltas && copied) scan.template operator()<true, true>();
  else if (renders.deltas) scan.template operator()<true, false>();
  else if (copied) scan.template operator()<false, true>();
  else scan.template operator()<false, false>();
  for (int j = 0; j < J; ++j)  // the lookup back to all -1 for the next call
    if (label_of(j) >= 0) label_obj_[label_of(j)] = -1;
  renders_ = renders;  // what the crops read: the renders themselves, or the copy as complete values
  renders_.base_color = base_pred_.data();
  renders_.base_stride = 3;
  renders_.base_opacity = base_opac_.data();
  renders_.base_opacity_stride = 1;
  if (copied) {
    for (int j = 0; j < J; ++j) {
      renders_.color[j] = &planes_[size_t(j) * HW * 4];
      renders_.opacity[j] = renders_.color[j] + 3;
    }
    renders_.stride = 4;
    renders_.deltas = false;
    renders_.live = nullptr;  // (the copies hold the +0 values)
  }
  const int dep = dep_ = opt_.dilation >= 0 ? opt_.dilation : dependency_radius(cfg_);
  obj_.resize(J);
  // The hull of rows' column ranges [lo, hi] (hi < 0: none in the row).
  auto hull = [&](const std::vector<int>& lo, const std::vector<int>& hi, int j) {
    PixelBox b{W, H, 0, 0};
    for (int y = 0; y < H; ++y) {
      if (hi[size_t(j) * H + y] < 0) continue;
      b.x0 = std::min(b.x0, lo[size_t(j) * H + y]);
      b.x1 = std::max(b.x1, hi[size_t(j) * H + y] + 1);
      b.y0 = std::min(b.y0, y);
      b.y1 = y + 1;
    }
    return b;
  };
  for (int j = 0; j < J; ++j) {
    const PixelBox D = hull(row_lo_, row_hi_, j);
    Object& o = obj_[j];
    o.M = hull(mask_lo_, mask_hi_, j);
    o.R = D.grown(dep, W, H);
    o.Q = o.R.grown(dep, W, H);
    o.full = double(o.Q.area()) > opt_.max_box_fraction * double(HW);
    if (o.full) o.R = o.Q = PixelBox{0, 0, W, H};
  }
}

}  // namespace hgs::hybrid
