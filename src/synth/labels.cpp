// Polygon labels from binary masks, in the form LERF-OVS labels take and cv2.fillPoly reads back (eval/labels.cpp):
// each 8-connected part's outer boundary traced through the centres of its boundary pixels (Moore-neighbour
// tracing, clockwise in image coordinates, the contour cv2.findContours gives), consecutive points 8-neighbours,
// then runs in one direction merged into one segment (horizontal, vertical and 45-degree lines are drawn by
// OpenCV's line exactly on those pixels). Filling the polygon as cv2.fillPoly does gives the part back with its
// holes filled. A one-pixel part is the point repeated three times (a polygon needs three vertices).
#include <algorithm>
#include <cstdlib>
#include <unordered_map>

#include "synth/synth.h"

namespace hgs::synth {

std::vector<std::vector<std::pair<int, int>>> trace_polygons(const std::vector<uint8_t>& inside, int w, int h) {
  std::vector<int> comp(size_t(w) * h, -1);
  std::vector<std::vector<int>> parts;
  for (int y0 = 0; y0 < h; ++y0)
    for (int x0 = 0; x0 < w; ++x0) {
      size_t i0 = size_t(y0) * w + x0;
      if (!inside[i0] || comp[i0] >= 0) continue;
      int id = static_cast<int>(parts.size());
      parts.emplace_back();
      std::vector<int> stack = {static_cast<int>(i0)};
      comp[i0] = id;
      while (!stack.empty()) {
        int i = stack.back();
        stack.pop_back();
        parts[id].push_back(i);
        int x = i % w, y = i / w;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
            size_t j = size_t(ny) * w + nx;
            if (inside[j] && comp[j] < 0) {
              comp[j] = id;
              stack.push_back(static_cast<int>(j));
            }
          }
      }
    }
  // Directions clockwise in image coordinates (y down), starting east.
  static const int DX[8] = {1, 1, 0, -1, -1, -1, 0, 1}, DY[8] = {0, 1, 1, 1, 0, -1, -1, -1};
  std::vector<std::vector<std::pair<int, int>>> polys;
  for (size_t id = 0; id < parts.size(); ++id) {
    auto in = [&](int x, int y) { return x >= 0 && y >= 0 && x < w && y < h && comp[size_t(y) * w + x] == int(id); };
    // Start: the part's first pixel in raster order; nothing of the part lies north of it or west of it.
    int start = *std::min_element(parts[id].begin(), parts[id].end());
    const int sx = start % w, sy = start / w;
    std::vector<std::pair<int, int>> pts = {{sx, sy}};
    std::vector<int> dirs;
    int x = sx, y = sy, d = 0;  // as if arrived moving east: search from north, clockwise
    int first_dir = -1;
    for (size_t guard = 0; guard < 8 * parts[id].size() + 8; ++guard) {
      int found = -1;
      for (int k = 0; k < 8; ++k) {
        const int nd = (d + 6 + k) % 8;  // from "back-left" of the arrival direction, clockwise
        if (in(x + DX[nd], y + DY[nd])) {
          found = nd;
          break;
        }
      }
      if (found < 0) break;                                 // a single pixel
      if (x == sx && y == sy && found == first_dir) break;  // Jacob's stopping criterion
      if (first_dir < 0) first_dir = found;
      x += DX[found];
      y += DY[found];
      d = found;
      dirs.push_back(found);
      pts.emplace_back(x, y);
    }
    if (dirs.empty()) {
      polys.push_back({{sx, sy}, {sx, sy}, {sx, sy}});
      continue;
    }
    pts.pop_back();  // the walk ends back at the start
    // Keep a point where the direction changes (the start always).
    std::vector<std::pair<int, int>> poly;
    const size_t m = pts.size();
    for (size_t k = 0; k < m; ++k)
      if (k == 0 || dirs[k - 1] != dirs[k]) poly.push_back(pts[k]);
    while (poly.size() < 3) poly.push_back(poly.back());
    polys.push_back(std::move(poly));
  }
  return polys;
}

}  // namespace hgs::synth
