// Tile binning: per-Gaussian boxes, pair numbering (prefix sum by chunks), LSD radix sort of depth keys (stable,
// per-thread digit counts), scatter into per-tile lists by chunks of the depth-sorted Gaussians (per-thread tile
// counts, lists laid out tile-major then chunk-major): every step on the OpenMP threads, results independent of
// their count. See binning.h.
#include "render/binning.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/parallel.h"
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
  // The bits that differ between keys: a digit without any is the same everywhere and its pass is skipped
  // without counting (counting it would add every key to one counter, a chain of dependent increments).
  uint64_t varying = 0;
  const uint64_t k0 = m > 0 ? keys[0] : 0;
#pragma omp parallel for num_threads(T) reduction(| : varying) schedule(static)
  for (size_t i = 0; i < m; ++i) varying |= keys[i] ^ k0;
  for (int pass = 0; pass < key_bytes; ++pass) {
    const int shift = 8 * pass;
    if (((varying >> shift) & 255) == 0) continue;
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

// Sizes b's per-Gaussian arrays and the tile grid of a width x height image.
void start_binning(int width, int height, int n, Binning& b) {
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
}

// 1. Gaussian i's boxes: bb [4] the pixel box of its alpha >= 1/255 ellipse (inclusive x0, x1, y0, y1; empty as
// 1, 0), tr [4] the tiles of that box clipped to its projected radius; its pair count and its ellipse's
// Mahalanobis bound m (-1 when it cannot reach alpha 1/255).
template <class T>
inline void gaussian_box(const Binning& b, int i, const T* mean2d, const T* conic, const T* opacity, const int* radius,
                         int* bb, int* tr, int& count, double& mahal) {
  bb[0] = tr[0] = 1;
  bb[1] = tr[1] = 0;
  bb[2] = tr[2] = 1;
  bb[3] = tr[3] = 0;
  count = 0;
  mahal = -1;
  const T o = opacity[i];
  if (radius[i] <= 0 || !(o * T(kAlphaMinInverse) >= T(1))) return;
  const int width = b.width, height = b.height;
  const T u = mean2d[2 * i], v = mean2d[2 * i + 1];
  const T a = conic[3 * i], bc = conic[3 * i + 1], c = conic[3 * i + 2];
  const T det = a * c - bc * bc;
  // alpha >= 1/255 needs d^T conic d <= m; bounding box of that ellipse is +-sqrt(m * cov_xx), +-sqrt(m * cov_yy)
  const T m = T(2) * std::log(T(kAlphaMinInverse) * o) * T(1.0001) + T(1e-4);
  mahal = double(m);
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
  if (x0 > x1 || y0 > y1 || bb[0] > bb[1] || bb[2] > bb[3]) return;
  tr[0] = x0 / kTileSize;
  tr[1] = x1 / kTileSize;
  tr[2] = y0 / kTileSize;
  tr[3] = y1 / kTileSize;
  count = (tr[1] - tr[0] + 1) * (tr[3] - tr[2] + 1);
}

// 2. Gaussian-major pair numbering (pair_offset [n + 1]) and the depth keys and order of the binned Gaussians: a
// two-pass prefix sum over contiguous chunks of Gaussians (sums per chunk, then each chunk numbers its pairs and
// places its binned Gaussians from its offsets), so the result is the serial loop's. Returns the pair count.
template <class T>
int number_pairs(int n, const T* depth, Binning& b) {
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
  return total;
}

// The write cursors of the tile lists: cursor [nt, num_tiles] holds each chunk's pair count per tile and
// becomes each chunk's first slot in each tile's list (tile-major, then chunk-major); tile_start [num_tiles + 1]
// gets the lists' starts.
inline void tile_cursors(int nt, int num_tiles, int* cursor, int* tile_start) {
  int run = 0;
  for (int tile = 0; tile < num_tiles; ++tile) {
    tile_start[tile] = run;
    for (int u = 0; u < nt; ++u) {
      int& c = cursor[size_t(u) * num_tiles + tile];
      const int cnt = c;
      c = run;
      run += cnt;
    }
  }
  tile_start[num_tiles] = run;
}

// 3. per-tile lists: the depth-sorted Gaussians in contiguous chunks, one per thread. Each thread counts its
// chunk's pairs per tile; the lists are laid out tile-major, then chunk-major inside a tile (so every list stays
// in depth order), and each thread writes its own chunk's entries: the serial scan's lists, whatever the thread
// count, with each thread reading only its chunk (splitting the tile rows instead made every thread scan every
// Gaussian, which did not get faster with more threads).
void build_tile_lists(int total, Binning& b) {
  const int m = int(b.order.size());
  const int T3 = m < 4096 ? 1 : std::max(1, omp_get_max_threads());
  b.tile_start.assign(size_t(b.num_tiles) + 1, 0);
  b.cursor.assign(size_t(T3) * b.num_tiles, 0);  // [T3, num_tiles] counts, then write cursors
  b.tile_gauss.resize(size_t(total));
  b.tile_pair.resize(size_t(total));
  b.sorted_rect.resize(size_t(m) * 4);  // the tile rects in depth order, read in sequence by both scans
  // Locals: the loops write ints, which could alias the members and the vectors' own fields.
  const int tiles_x = b.tiles_x, num_tiles = b.num_tiles;
  int *cursor = b.cursor.data(), *srect = b.sorted_rect.data(), *tgauss = b.tile_gauss.data(),
      *tpair = b.tile_pair.data(), *tstart = b.tile_start.data();
  const int *trect = b.trect.data(), *order = b.order.data(), *poff = b.pair_offset.data();
#pragma omp parallel num_threads(T3)
  {
    const int t = omp_get_thread_num(), nt = omp_get_num_threads();
    const int k0 = int(int64_t(m) * t / nt), k1 = int(int64_t(m) * (t + 1) / nt);
    int* cur = cursor + size_t(t) * num_tiles;
    // the gather first, in its own loop (independent loads in flight), then the counts from the copy
    for (int k = k0; k < k1; ++k) std::memcpy(srect + 4 * size_t(k), trect + 4 * size_t(order[k]), 4 * sizeof(int));
    for (int k = k0; k < k1; ++k) {
      const int* tr = srect + 4 * size_t(k);
      const int x0 = tr[0], x1 = tr[1], y0 = tr[2], y1 = tr[3];
      for (int ty = y0; ty <= y1; ++ty)
        for (int tx = x0; tx <= x1; ++tx) ++cur[ty * tiles_x + tx];
    }
#pragma omp barrier
#pragma omp single
    tile_cursors(nt, num_tiles, cursor, tstart);  // implicit barrier
    for (int k = k0; k < k1; ++k) {
      const int* tr = srect + 4 * size_t(k);
      const int g = order[k], x0 = tr[0], x1 = tr[1], y0 = tr[2], y1 = tr[3];
      const int w = x1 - x0 + 1, p0 = poff[g];
      for (int ty = y0; ty <= y1; ++ty)
        for (int tx = x0; tx <= x1; ++tx) {
          const int pos = cur[ty * tiles_x + tx]++;
          tgauss[pos] = g;
          tpair[pos] = p0 + (ty - y0) * w + (tx - x0);
        }
    }
  }
}

}  // namespace

template <class T>
void bin_gaussians(int width, int height, int n, const T* mean2d, const T* conic, const T* opacity, const T* depth,
                   const int* radius, Binning& b) {
  start_binning(width, height, n, b);
  // On demand (demand_chunk): the visible Gaussians (the work) cluster by index after densification.
#pragma omp parallel for schedule(dynamic, demand_chunk(n, 128))
  for (int i = 0; i < n; ++i)
    gaussian_box(b, i, mean2d, conic, opacity, radius, &b.bbox[4 * size_t(i)], &b.trect[4 * size_t(i)], b.counts[i],
                 b.mahal[i]);
  const int total = number_pairs(n, depth, b);
  b.num_pairs = total;
  radix_sort(b.keys, b.order, b.keys_tmp, b.order_tmp, int(sizeof(T) == 4 ? 4 : 8));
  build_tile_lists(total, b);
}

template void bin_gaussians<float>(int, int, int, const float*, const float*, const float*, const float*, const int*,
                                   Binning&);
template void bin_gaussians<double>(int, int, int, const double*, const double*, const double*, const double*,
                                    const int*, Binning&);

}  // namespace hgs::render
