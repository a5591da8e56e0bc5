// Structural similarity as in 3DGS's loss_utils.ssim: 11x11 Gaussian window (sigma 1.5, normalised), 'same'
// size output with zero padding, C1 = 0.01^2, C2 = 0.03^2, each channel separately, mean of the SSIM map
// over all pixels and channels. Templated on the scalar type so tests can run the same code in double.
#pragma once
#include <functional>
#include <vector>

#include "core/scratch_vector.h"

namespace hgs::train {

// (ScratchVector: the passes write every value they read; growth is not zeroed.)
template <typename T>
struct SsimWorkspace {
  std::vector<ScratchVector<T>> band;  // per row band: line buffers (96 rows of W*C); reused between calls
  std::vector<double> row_sum;         // [H] SSIM-map sum of each row
  ScratchVector<T> coeff;              // [H, 3, W*C] horizontally filtered backward coefficients (with a gradient);
                                       // ssim_rows_streamed: [48, W*C], its ring and rows
};

// Mean SSIM of images x and y, both [H, W, C] (channel-interleaved). When `grad_x` is not null it receives
// d(mean SSIM)/dx, [H, W, C] (overwritten). Uses OpenMP over bands of rows (a single band inside a parallel
// region); deterministic and independent of the thread count.
template <typename T>
T ssim(const T* x, const T* y, int H, int W, int C, T* grad_x, SsimWorkspace<T>& ws);

// ssim() with extras for scoring part of an image (hybrid/object_losses.cpp scores crops): `map` (may be null)
// receives the SSIM map [H, W, C], and `grad_x` receives d(sum of the map / count)/dx (count = H W C is ssim()'s
// mean; a crop of a larger image passes the larger image's count). y may be null for an all-zero image (the same
// values as zeros, with the passes of its three zero moments skipped). Returns the mean over H W C.
template <typename T>
T ssim_map(const T* x, const T* y, int H, int W, int C, T* grad_x, T* map, double count, SsimWorkspace<T>& ws);

// Where y may be non-zero: pixel columns [x0, x1) of rows [y0, y1) (clipped to the image; y must be zero
// outside). y's three moments are then non-zero only within 5 pixels of it, and the term of the gradient that
// y multiplies is needed only inside it, so their passes run there alone (an object's masked target inside its
// crop: hybrid/object_losses.cpp).
struct SsimSupport {
  int x0 = 0, y0 = 0, x1 = 1 << 30, y1 = 1 << 30;
};

// ssim_map for output rows [y0, y1) and output columns [x0, x1) only: grad_x there, bitwise the values ssim_map
// gives them (a gradient value that is 0 may differ in its sign), and the map there and 5 columns further (other
// values are not written; ssim_rows_streamed below, stored); the moments are computed for rows [y0 - 5, y1 + 5) and
// columns [x0 - 5, x1 + 5), the products for 5 more on each side. One band, single-threaded (for scoring a band of a
// larger image inside a parallel region). `ys`: where y may be non-zero (default: anywhere).
template <typename T>
void ssim_map_rows(const T* x, const T* y, int H, int W, int C, int y0, int y1, T* grad_x, T* map, double count,
                   SsimWorkspace<T>& ws, SsimSupport ys = {}, int x0 = 0, int x1 = 1 << 30);

// ssim_map_rows streamed: the same values, handed to `sink` row by row instead of stored, with every intermediate
// (the products' and moments' rows, the map and the coefficients of the last 11 rows, the gradient row) in
// buffers of a few rows, so that a pass over a large image moves x, y and what the sink keeps, nothing else.
// x and y by row: xrow(r), yrow(r) [W C] for the rows [y0 - 10, y1 + 10) (clipped), first asked for in increasing
// order, none more than 10 rows before the latest asked for (so a ring of 11 rows or more can hold them); yrow empty
// for an all-zero y. sink(r, grad, map) for r = y0 .. y1 - 1 in order: grad's values [x0 C, x1 C) and map's
// [max(0, x0 - 5) C, min(W, x1 + 5) C) are row r's, each indexed by its place in the row (valid during the call).
template <typename T>
using SsimRow = std::function<const T*(int)>;
template <typename T>
using SsimSink = std::function<void(int, const T*, const T*)>;
template <typename T>
void ssim_rows_streamed(const SsimRow<T>& xrow, const SsimRow<T>& yrow, int H, int W, int C, int y0, int y1,
                        double count, SsimWorkspace<T>& ws, const SsimSink<T>& sink, SsimSupport ys = {}, int x0 = 0,
                        int x1 = 1 << 30);

// The normalised 1D window (11 taps) shared by the forward and the tests.
template <typename T>
const T* ssim_window();

}  // namespace hgs::train
