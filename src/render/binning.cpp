// Tile binning: per-Gaussian boxes, pair numbering (prefix sum by chunks), LSD radix sort of depth keys (stable,
// per-thread digit counts), scatter into per-tile lists by chunks of tile rows (each chunk scans the
// depth-sorted Gaussians' tile rects once): every step on the OpenMP threads, results independent of their
// count. See binning.h.
#include "render/binning.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "render/rasterize.h"  // the alpha cut-off kAlphaMin = 1 / kAlphaMinInverse

namespace hgs::render {
namespace {

// Monotone unsigned key of a float / double (works for negative values too).
inline uint64_t depth_key(float d) {
  uint32_t u;
  std::memcpy(&u, &d, 4);
  u = (u & 0x80000000u) ? ~u : (u | 0x80000000u);
  return u;
}
inline uint64_t depth_key(double d) {
  uint64_t u;
  std::memcpy(&u, &d, 8);
  return (u & 0x8000000000000000ull) ? ~u : (u | 0x8000000000000000ull);
}

// Stable LSD radix sort of (key, value) pairs, 8-bit digits, skipping digits that are equal everywhere. Each
// pass runs on the OpenMP threads: thread t counts the digits of its contiguous chunk, the scatter offsets are
// laid out digit-major then thread-major, so every thread writes its chunk's entries in their order and the
// result is the serial stable sort's, whatever the thread count.
void radix_sort(std::vector<uint64_t>& keys, std::vector<int>& vals, std::vector<uint64_t>& ktmp,
                std::vector<int>& vtmp, int key_bytes) {
  const size_t m = keys.size();
  ktmp.resize(m);
  vtmp.resize(m);
  const int T = m < 8192 ? 1 : std::max(1, omp_get_max_threads());
  std::vector<size_t> hist(size_t(T) * 256);
  for (int pass = 0; pass < key_bytes; ++pass) {
    const int shift = 8 * pass;
    std::fill(hist.begin(), hist.end(), 0);
    bool trivial = false;
#pragma omp parallel num_threads(T)
    {
      const int t = omp_get_thread_num(), nt = omp_get_num_threads();
      const size_t c0 = m * size_t(t) / size_t(nt), c1 = m * size_t(t + 1) / size_t(nt);
      size_t* h = hist.data() + size_t(t) * 256;
      for (size_t i = c0; i < c1; ++i) ++h[(keys[i] >> shift) & 255];
#pragma omp barrier
#pragma omp single
      {
        // Exclusive offsets, digit-major then thread-major (hist becomes the write cursors).
        size_t run = 0;
        for (int d = 0; d < 256; ++d) {
          size_t total = 0;
          for (int u = 0; u < nt; ++u) total += hist[size_t(u) * 256 + d];
          if (total == m) trivial = true;
          for (int u = 0; u < nt; ++u) {
            const size_t c = hist[size_t(u) * 256 + d];
            hist[size_t(u) * 256 + d] = run;
            run += c;
          }
        }
      }  // implicit barrier
      if (!trivial)
        for (size_t i = c0; i < c1; ++i) {
          const size_t pos = h[(keys[i] >> shift) & 255]++;
          ktmp[pos] = keys[i];
          vtmp[pos] = vals[i];
        }
    }
    if (trivial) continue;
    keys.swap(ktmp);
    vals.swap(vtmp);
  }
}

template <class T>
inline int clamp_floor(T v, int lo, int hi) {
  v = std::floor(v);
  if (!(v >= T(lo))) return lo;
  if (v > T(hi)) return hi;
  return int(v);
}
template <class T>
inline int clamp_ceil(T v, int lo, int hi) {
  v = std::ceil(v);
  if (!(v >= T(lo))) return lo;
  if (v > T(hi)) return hi;
  return int(v);
}

}  // namespace

template <class T>
void bin_gaussians(int width, int height, int n, const T* mean2d, const T* conic, const T* opacity, const T* depth,
                   const int* radius, Binning& b) {
  b.width = width;
  b.height = height;
  b.tiles_x = (width + kTileSize - 1) / kTileSize;
  b.tiles_y = (height + kTileSize - 1) / kTileSize;
  b.num_tiles = b.tiles_x * b.tiles_y;
  b.bbox.resize(size_t(n) * 4);
  b.trect.resize(size_t(n) * 4);
  b.pair_offset.resize(size_t(n) + 1);
  b.counts.resize(size_t(n));
  b.mahal.resize(size_t(n));

  // 1. boxes
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    int* bb = &b.bbox[4 * size_t(i)];
    int* tr = &b.trect[4 * size_t(i)];
    bb[0] = tr[0] = 1;
    bb[1] = tr[1] = 0;
    bb[2] = tr[2] = 1;
    bb[3] = tr[3] = 0;
    b.counts[i] = 0;
    b.mahal[i] = -1;
    const T o = opacity[i];
    if (radius[i] <= 0 || !(o * T(kAlphaMinInverse) >= T(1))) continue;
    const T u = mean2d[2 * i], v = mean2d[2 * i + 1];
    const T a = conic[3 * i], bc = conic[3 * i + 1], c = conic[3 * i + 2];
    const T det = a * c - bc * bc;
    // alpha >= 1/255 needs d^T conic d <= m; bounding box of that ellipse is +-sqrt(m * cov_xx), +-sqrt(m * cov_yy)
    const T m = T(2) * std::log(T(kAlphaMinInverse) * o) * T(1.0001) + T(1e-4);
    b.mahal[i] = double(m);
    const T ex = std::sqrt(std::max(T(0), m * c / det)) + T(1e-3);
    const T ey = std::sqrt(std::max(T(0), m * a / det)) + T(1e-3);
    // pixel x is evaluated at x + 0.5
    bb[0] = clamp_ceil(u - ex - T(0.5), 0, width);
    bb[1] = clamp_floor(u + ex - T(0.5), -1, width - 1);
    bb[2] = clamp_ceil(v - ey - T(0.5), 0, height);
    bb[3] = clamp_floor(v + ey - T(0.5), -1, height - 1);
    const T r = T(radius[i]);
    const int sx0 = clamp_ceil(u - r - T(0.5), 0, width), sx1 = clamp_floor(u + r - T(0.5), -1, width - 1);
    const int sy0 = clamp_ceil(v - r - T(0.5), 0, height), sy1 = clamp_floor(v + r - T(0.5), -1, height - 1);
    const int x0 = std::max(sx0, bb[0]), x1 = std::min(sx1, bb[1]);
    const int y0 = std::max(sy0, bb[2]), y1 = std::min(sy1, bb[3]);
    if (x0 > x1 || y0 > y1 || bb[0] > bb[1] || bb[2] > bb[3]) continue;
    tr[0] = x0 / kTileSize;
    tr[1] = x1 / kTileSize;
    tr[2] = y0 / kTileSize;
    tr[3] = y1 / kTileSize;
    b.counts[i] = (tr[1] - tr[0] + 1) * (tr[3] - tr[2] + 1);
  }

  // 2. Gaussian-major pair numbering and the depth order of binned Gaussians: a two-pass prefix sum over
  // contiguous chunks of Gaussians (sums per chunk, then each chunk numbers its pairs and places its binned
  // Gaussians from its offsets), so the result is the serial loop's.
  const int T2 = n < 8192 ? 1 : std::max(1, omp_get_max_threads());
  std::vector<int64_t> chunk_pairs(size_t(T2) + 1, 0), chunk_binned(size_t(T2) + 1, 0);
  int total = 0, binned = 0;
#pragma omp parallel num_threads(T2)
  {
    const int t = omp_get_thread_num(), nt = omp_get_num_threads();
    const int i0 = int(int64_t(n) * t / nt), i1 = int(int64_t(n) * (t + 1) / nt);
    int64_t p = 0, q = 0;
    for (int i = i0; i < i1; ++i) p += b.counts[i], q += b.counts[i] > 0;
    chunk_pairs[size_t(t) + 1] = p;
    chunk_binned[size_t(t) + 1] = q;
#pragma omp barrier
#pragma omp single
    {
      for (int u = 0; u < nt; ++u) {
        chunk_pairs[size_t(u) + 1] += chunk_pairs[u];
        chunk_binned[size_t(u) + 1] += chunk_binned[u];
      }
      total = int(chunk_pairs[size_t(nt)]);
      binned = int(chunk_binned[size_t(nt)]);
      b.keys.resize(size_t(binned));
      b.order.resize(size_t(binned));
    }  // implicit barrier
    int run = int(chunk_pairs[t]), k = int(chunk_binned[t]);
    for (int i = i0; i < i1; ++i) {
      b.pair_offset[i] = run;
      run += b.counts[i];
      if (b.counts[i] > 0) {
        b.keys[k] = depth_key(depth[i]);
        b.order[k++] = i;
      }
    }
  }
  b.pair_offset[n] = total;
  b.num_pairs = total;
  radix_sort(b.keys, b.order, b.keys_tmp, b.order_tmp, int(sizeof(T) == 4 ? 4 : 8));

  // 3. per-tile lists: chunks of tile rows in parallel, each scanning the sorted Gaussians
  b.tile_start.assign(size_t(b.num_tiles) + 1, 0);
  b.cursor.resize(size_t(b.num_tiles));
  b.tile_gauss.resize(size_t(total));
  b.tile_pair.resize(size_t(total));
  const int m = int(b.order.size());
  const int nthreads = std::max(1, std::min(omp_get_max_threads(), b.tiles_y));
  // The tile rects in depth order, so that both scans below read them in sequence.
  b.sorted_rect.resize(size_t(m) * 4);
#pragma omp parallel for schedule(static) num_threads(nthreads)
  for (int k = 0; k < m; ++k)
    std::memcpy(&b.sorted_rect[4 * size_t(k)], &b.trect[4 * size_t(b.order[k])], 4 * sizeof(int));
#pragma omp parallel num_threads(nthreads)
  {
    const int tid = omp_get_thread_num(), nt = omp_get_num_threads();
    const int r0 = int(int64_t(b.tiles_y) * tid / nt), r1 = int(int64_t(b.tiles_y) * (tid + 1) / nt);
    int* start = b.tile_start.data();
    for (int k = 0; k < m; ++k) {
      const int* tr = &b.sorted_rect[4 * size_t(k)];
      const int ty0 = std::max(tr[2], r0), ty1 = std::min(tr[3], r1 - 1);
      for (int ty = ty0; ty <= ty1; ++ty)
        for (int tx = tr[0]; tx <= tr[1]; ++tx) ++start[ty * b.tiles_x + tx + 1];
    }
#pragma omp barrier
#pragma omp single
    {
      for (int t = 0; t < b.num_tiles; ++t) start[t + 1] += start[t];
    }
    // write cursors of this chunk's tiles (each thread owns its rows of the shared cursor array)
    int* cursor = b.cursor.data() + size_t(r0) * b.tiles_x;
    for (int ty = r0; ty < r1; ++ty)
      for (int tx = 0; tx < b.tiles_x; ++tx) cursor[size_t(ty - r0) * b.tiles_x + tx] = start[ty * b.tiles_x + tx];
    for (int k = 0; k < m; ++k) {
      const int* tr = &b.sorted_rect[4 * size_t(k)];
      const int ty0 = std::max(tr[2], r0), ty1 = std::min(tr[3], r1 - 1);
      if (ty0 > ty1) continue;
      const int g = b.order[k];
      const int w = tr[1] - tr[0] + 1;
      for (int ty = ty0; ty <= ty1; ++ty)
        for (int tx = tr[0]; tx <= tr[1]; ++tx) {
          const int pos = cursor[size_t(ty - r0) * b.tiles_x + tx]++;
          b.tile_gauss[pos] = g;
          b.tile_pair[pos] = b.pair_offset[g] + (ty - tr[2]) * w + (tx - tr[0]);
        }
    }
  }
}

template void bin_gaussians<float>(int, int, int, const float*, const float*, const float*, const float*, const int*,
                                   Binning&);
template void bin_gaussians<double>(int, int, int, const double*, const double*, const double*, const double*,
                                    const int*, Binning&);

}  // namespace hgs::render
