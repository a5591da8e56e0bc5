// The object-conditioned losses of one view: eq. 6 (appearance, (1 - lambda) L1 + lambda (1 - SSIM) of each
// object render I_k against I * M_k) and eq. 14 (BRO on the band of eq. 13, with the scale rule and the
// scale-invariant gradient of bro.h), for the J objects present in the view's mask. The object renders come from
// one rasterization (ObjectRenders below: the dense object channels of object_channels.h, or the base channels
// and groups of object_groups.h, interleaved per pixel or one plane per object); where the objects are
// interleaved, the box path's first pass lays each object's render out as its own plane, so that an object's crop
// reads contiguous rows. Each object's losses run single-threaded in one thread's scratch (no parallel-region
// overhead per convolution), and the gradients go back interleaved per pixel (ObjectGradOut) or stay in sparse
// form for the renderer to read on demand (gradient_row). Loss values are summed in object order (deterministic,
// independent of the thread count). A crop is scored in one pass down its rows (score_crop): SSIM's rows come
// out of train::ssim_rows_streamed in order, computed only for the columns its outputs need and with the
// target's passes only on and near the mask's box (bitwise the full passes), and eq. 14's band and parts follow
// row by row (BandRows, BroRows), so that nothing but a few rows of the crop and the outputs is written: the
// passes stay in a core's own cache instead of streaming crop-sized buffers through the shared one.
//
// Boxes (ObjectLossOptions::boxes, with the layout's base render). Every term of both losses is a sum over
// pixels p (L1 and the SSIM map over pixels, eq. 14's numerator and band weights over the forward differences,
// charged to their first pixel) divided by a global normaliser (3 H W, or eq. 14's band total), and every
// gradient at p is a sum of local terms times global scalars. Object k's inputs (colour, opacity, mask, I * M_k)
// equal those of the "base pair" (the base render against an all-zero target, mask 0) outside the box D_k of
// the pixels where its colour or opacity channels differ bitwise from the base channels or its label is k. The
// terms at p read the inputs within a radius: the SSIM map 5, its gradient 10, eq. 14's band s/2 and its
// differences one more. So with R_k = D_k grown by dep = max(10, s/2 + 1), every per-pixel term and local
// gradient of object k outside R_k is the base pair's, bitwise. Hence, exactly (up to reassociation):
//   sum_k = sum_base - sum_base over R_k + sum_k over R_k     (for L1, the SSIM map, eq. 14's numerator and band
//                                                               weight, and BRO's dot products <g, p>, <p, p>)
// and object k's gradient is its own inside R_k and, outside, s_app G_base + gs_k U_base - a_k P_base, where
// G_base is eq. 6's gradient of the base pair, U_base eq. 14's unscaled gradient (bro_parts), P_base the base
// render, gs_k eq. 14's global scale (from the band total) and a_k the projection coefficient of
// remove_scale_component (from the two dot products). Object k's terms inside R_k come from a crop Q_k = R_k
// grown by dep again: every term inside R_k reads only pixels of Q_k, and where Q_k's edge is not the image's,
// the crop's own border handling (zero padding, clipped windows) affects only pixels outside R_k. The base pair
// is scored once per view over the whole image (eq. 6, eq. 14). Objects whose crop covers more than
// max_box_fraction of the image (typically the background) are scored over the whole image, like the others
// through the sums and scalars above (with no base part).
// Bands. The same argument splits any scored region by rows: a band of rows [y0, y1) of R_k, cropped with dep
// rows above and below, gives R_k's terms in those rows bitwise. Each task (the base pair's two, every object)
// is cut into bands so that no piece is a large part of the whole work (by the thread count, at least 24 rows
// each; one band at one thread), the pieces run largest first on a dynamic schedule, and every sum is kept per
// row and added in row order: values and gradients are bitwise the same for any banding, so at any thread count.
#pragma once
#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include "core/image.h"
#include "core/scratch_vector.h"
#include "hybrid/bro.h"
#include "hybrid/config.h"
#include "hybrid/object_channels.h"
#include "train/loss.h"

namespace hgs::hybrid {

struct ObjectLossValues {
  double app = 0;  // mean of eq. 6 over the objects
  double bro = 0;  // mean of eq. 14 over the objects, each weighted by the scale rule (the term as optimised)
};

// The objects scored in one step under HybridConfig::objects_per_step = m: m of `present` [J] drawn uniformly
// without replacement (partial Fisher-Yates on rng), returned in their order in `present`; all of them when m is 0
// or m >= J.
std::vector<int> sample_objects(const std::vector<int>& present, int m, std::mt19937_64& rng);

// A pixel rectangle [x0, x1) x [y0, y1).
struct PixelBox {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool empty() const { return x0 >= x1 || y0 >= y1; }
  int width() const { return empty() ? 0 : x1 - x0; }
  int height() const { return empty() ? 0 : y1 - y0; }
  size_t area() const { return size_t(width()) * height(); }
  PixelBox grown(int r, int W, int H) const;  // by r on every side, clipped to the W x H image (empty stays empty)
};

struct ObjectLossOptions {
  bool boxes = true;              // score objects inside their boxes when the layout has the base render
  double max_box_fraction = 0.8;  // an object whose crop covers more of the image is scored over the whole image
  int dilation = -1;              // the radius dep of the header (< 0: the exact one; tests shrink it)
  int band_rows = 0;              // rows per band of the box path (0: by the thread count; tests set it)
};

// The colour gradient of the last call in sparse form: object j's gradient is own[j] [box h, box w, 3] inside
// box[j] and app_scale * base_app + bro_scale[j] * base_unit - proj[j] * base_pred outside it (base_* [H, W, 3];
// base_unit only when some bro_scale is non-zero). box[j] is the whole image for objects scored over it.
struct ObjectGradients {
  std::vector<PixelBox> box;           // [J]
  std::vector<const float*> own;       // [J]
  float app_scale = 0;                 // lambda_app / J
  std::vector<float> bro_scale, proj;  // [J]
  const float *base_app = nullptr, *base_unit = nullptr, *base_pred = nullptr;
};

// Where one view's object renders are. Either complete, as the dense object channels come from the renderer
// (interleaved in an ObjectLayout: pixel p of object j has its colour at color[j] + p * stride, 3 floats, and its
// opacity at opacity[j][p * stride]), or as the sparse path renders them (object_groups.h): the base render's
// dense channels and, interleaved likewise, each object's group, its difference from the base render (deltas):
// object j's value is then base + difference, the sum the dense layout's channel holds (the same floats). The base
// render is at base_color + p * base_stride and base_opacity[p * base_opacity_stride] (null without it).
struct ObjectRenders {
  std::vector<const float*> color, opacity;  // [J]
  const float *base_color = nullptr, *base_opacity = nullptr;
  long stride = 0, base_stride = 0, base_opacity_stride = 0;
  bool deltas = false;
  // Tiles of tile x tile pixels where the renderer left an object's plane unwritten (planes with
  // render::ChannelsT::group_live_tiles): object j's value in color[j] / opacity[j] is +0 at (x, y) when
  // live[j * tiles + (y / tile) * tiles_x + x / tile] is 0, whatever its memory holds. Null: all are in memory.
  const uint8_t* live = nullptr;  // [J, tiles]
  int tile = 1, tiles_x = 0;
  long tiles = 0;
  int J() const { return static_cast<int>(color.size()); }
  // Whether object j's values at (x, y) are in memory, and the end of the run of columns from x that share it
  // (x's tile's last column + 1, at most end).
  bool in_memory(int j, int x, int y) const { return !live || live[j * tiles + long(y / tile) * tiles_x + x / tile]; }
  int run_end(int x, int end) const { return live ? std::min(end, (x / tile + 1) * tile) : end; }
  // Object j's colour channel c and opacity at pixel p; in = in_memory(j, x, y) (else its value there is +0).
  float color_at(int j, long p, int c, bool in = true) const {
    const float v = in ? color[j][p * stride + c] : 0.f;
    return deltas ? base_color[p * base_stride + c] + v : v;
  }
  float opacity_at(int j, long p, bool in = true) const {
    const float v = in ? opacity[j][p * stride] : 0.f;
    return deltas ? base_opacity[p * base_opacity_stride] + v : v;
  }
  static ObjectRenders interleaved(const float* extra, const ObjectLayout& lay);  // extra [H, W, lay.total()]
  // dense [H, W, dense_stride]: the base colour at 0..2, its opacity at base_opacity; groups [H, W, 4 J]: object
  // j's difference (colour, opacity) at 4 j; or, given planes = H W, groups [J, H, W, 4] (the renderer's
  // ChannelsT::group_planes).
  static ObjectRenders sparse(const float* dense, int dense_stride, int base_opacity, const float* groups, int J,
                              long planes = 0);
  // The renderer's flags of written tiles (live above; [J, tiles] for a width x height image).
  ObjectRenders& with_live_tiles(const uint8_t* flags, int tile_size, int width, int height);
};

// Where the losses write the objects' colour gradients: object j's at color + p * stride + 3 j (color null:
// nowhere, gradients() has them), and their sum over the objects at sum + p * sum_stride (sum null: not summed).
struct ObjectGradOut {
  float* color = nullptr;
  long stride = 0;
  float* sum = nullptr;
  long sum_stride = 3;
};

class ObjectLosses {
 public:
  explicit ObjectLosses(const HybridConfig& cfg, const ObjectLossOptions& opt = {}) : cfg_(cfg), opt_(opt) {}
  // image [H, W, 3]; labels [H, W] (confidence-filtered mask); renders the J objects' renders; objs [J] their
  // labels. Writes lambda_app * d(app) + lambda_bro * d(bro) of each object's colour to out.color (overwritten,
  // every pixel) and their sum over the J objects to out.sum (the sparse layout's base colour gradient,
  // object_groups.h).
  ObjectLossValues operator()(const Image& image, const LabelMap& labels, const ObjectRenders& renders,
                              const std::vector<int>& objs, const ObjectGradOut& out);
  // The same on the interleaved render of a layout: extra [H, W, C]; the gradients to the colour channels of
  // d_extra [H, W, C] (the other channels untouched; may be null) and, when given, their sum to color_sum [H, W, 3].
  ObjectLossValues operator()(const Image& image, const LabelMap& labels, const float* extra, const ObjectLayout& lay,
                              const std::vector<int>& objs, float* d_extra, float* color_sum = nullptr);
  // The last call's gradient, sparse (valid until the next call or release()).
  const ObjectGradients& gradients() const { return grads_; }
  // Object j's colour gradient of the last call at pixels (x0 .. x0 + n - 1, y): out [n, 3], the values out.color
  // would have held (bitwise). group_rows is the same for the renderer (render::OutputGradsT::group_rows, ctx =
  // this), which then needs no [H, W, 3 J] buffer.
  void gradient_row(int j, int y, int x0, int n, float* out) const;
  static void group_rows(const void* ctx, int j, int y, int x0, int n, float* out) {
    static_cast<const ObjectLosses*>(ctx)->gradient_row(j, y, x0, n, out);
  }
  // Wall time of the last call's phases of the box path, ms (0 on the path without boxes): finding the boxes,
  // the scoring pieces, the per-object scalars, the scatter of the gradients (bench_hybrid's counters); and the
  // tasks of the two phases that are not simply cut by rows of the image: the pieces (bands of the base pair's and
  // the objects' tasks) and the finish (one per object for its scalars, then bands of each object's rows).
  struct PhaseTimes {
    double boxes = 0, pieces = 0, finish = 0, scatter = 0;
    int pieces_tasks = 0, finish_tasks = 0;
  };
  const PhaseTimes& phase_times() const { return times_; }
  void release();

 private:
  // Per-thread buffers of the losses of one object, each in cache lines of its own (its row rings' state is written
  // on every row; a neighbour's fields in the same line would bounce between the two cores).
  struct alignas(64) Scratch {
    explicit Scratch(float lambda_dssim) : loss(lambda_dssim) {}
    train::PhotometricLoss loss;
    train::SsimWorkspace<float> ssim;
    // (ScratchVector: every use writes these before it reads them; their growth is not zeroed.)
    ScratchVector<float> gt, mask, band;  // [H, W, 3], [H, W], [H, W] (path without boxes)
    ScratchVector<float> bgrad;           // [H, W, 3] BRO's gradient before its scale component is removed
    // Box path, one pass down a crop or band (score_crop):
    ScratchVector<float> crop;         // [ring, 8 W] the crop's rows: colour, target [W, 3], mask, opacity [W]
    std::vector<float> zero;           // [W, 3] zeros: the base pair's mask and target rows
    ScratchVector<float> urow;         // [W, 3] a row of eq. 14's unscaled gradient
    ScratchVector<double> wrow, nrow;  // [W] a row of eq. 14's band weights and numerators (bro_parts)
    BandRows band_rows;
    BroRows<float> bro_rows;
    bool ring_overrun = false;  // score_crop read a crop row that had left its ring (a bug; box_path fails)
  };
  // The per-pixel terms of the box path: L1, SSIM map, eq. 14's band weight and numerator, <g, p>, <p, p>.
  enum Term { kL1, kSsim, kWsum, kNum, kGp, kPp, kTerms };
  struct Object {                 // one object of the box path
    PixelBox R, Q;                // scored box and crop (image coordinates)
    PixelBox M;                   // the box of its mask's pixels (its target I M_k is 0 outside)
    bool full = false;            // scored over the whole image (R = Q = the image)
    ScratchVector<float> own;     // [R h, R w, 3] its gradient inside R (every value written by the pieces)
    ScratchVector<float> unit;    // [R h, R w, 3] eq. 14's unscaled gradient inside R (bro_parts)
    ScratchVector<float> pred;    // [R h, R w, 3] the object's render inside R (for the projection)
    std::vector<double> rows;     // [R h, kTerms] its per-pixel terms summed over each row of R
    double base_in[kTerms] = {};  // the base pair's terms summed over R (raster order; boxes only)
    float bro_scale = 0, proj = 0;
  };

  ObjectLossValues full_path(const Image& image, const LabelMap& labels, const ObjectRenders& renders,
                             const std::vector<int>& objs, const ObjectGradOut& out);
  ObjectLossValues box_path(const Image& image, const LabelMap& labels, const ObjectRenders& renders,
                            const std::vector<int>& objs, const ObjectGradOut& out);
  void score_full(Scratch& w, const Image& image, const LabelMap& labels, int k, int J, const float* pred,
                  const float* opac, float* grad, double& app, double& bro);
  void find_boxes(const LabelMap& labels, const ObjectRenders& renders, const std::vector<int>& objs);
  void score_base_app(Scratch& w, int H, int W, int y0, int y1);
  void score_base_bro(Scratch& w, int H, int W, int y0, int y1);
  void score_crop(Scratch& w, const Image& image, const LabelMap& labels, int j, int k, int y0, int y1);
  void finish_box(int W, int H, int j);
  void complete_rows(int j, int r0, int r1);
  template <int kT0, int kT1>
  void base_sums(const PixelBox& r, int W, int H, double* out) const;
  void scatter(int H, int W, bool bro_grad, const ObjectGradOut& out) const;

  HybridConfig cfg_;
  ObjectLossOptions opt_;
  int width_ = 0;                   // the last call's image width
  std::vector<Scratch> scratch_;    // [threads]
  std::vector<float> pred_, grad_;  // [J, H, W, 3] planar object renders / gradients (path without boxes)
  std::vector<float> opac_;         // [J, H, W]
  std::vector<double> app_, bro_;   // [J]
  // Box path.
  std::vector<Object> obj_;                              // [J]
  std::vector<int> row_lo_, row_hi_;                     // [J, H] each row's differing columns
  std::vector<int> mask_lo_, mask_hi_;                   // [J, H] each row's columns of the object's label
  std::vector<int> label_obj_;                           // [65536] label -> its first object j (-1 between calls)
  std::vector<int> obj_next_;                            // [J] the next object with the same label (-1: none)
  std::vector<float> base_pred_, base_app_, base_unit_;  // [H, W, 3]
  std::vector<float> base_opac_;                         // [H, W]
  std::vector<float> planes_;                            // [J, H, W, 4] the objects' renders (colour, opacity)
  // The box path's renders as the crops read them (find_boxes): the call's objects, or planes_; the base render
  // as its planar copy base_pred_, base_opac_ (the same floats, read contiguously).
  ObjectRenders renders_;
  std::vector<double> base_terms_;  // [kTerms, H, W] planar: a task's box sums read their terms' planes alone
  std::vector<double> base_rows_;   // [H, kTerms] their sums over each row
  double base_total_[kTerms] = {};  // their sums over the image (the rows in order)
  int dep_ = 0;                     // the dependency radius in use
  ObjectGradients grads_;
  PhaseTimes times_;
};

}  // namespace hgs::hybrid
