// Polygon labels from binary masks. Each 8-connected part is traced along pixel edges: every pixel side
// between inside and outside becomes a directed edge (clockwise in image coordinates, inside on the right);
// edges are chained into loops, preferring a left turn where two diagonal pixels touch so that 8-connected
// pixels stay in one loop. The loop with the largest area is the part's outer boundary; collinear vertices
// are dropped. Filling the polygon with the even-odd rule at pixel centres gives the part back (holes filled).
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
            if (inside[j] && comp[j] < 0) { comp[j] = id; stack.push_back(static_cast<int>(j)); }
          }
      }
    }
  std::vector<std::vector<std::pair<int, int>>> polys;
  for (size_t id = 0; id < parts.size(); ++id) {
    auto in = [&](int x, int y) { return x >= 0 && y >= 0 && x < w && y < h && comp[size_t(y) * w + x] == int(id); };
    struct Edge { int x0, y0, x1, y1; bool used; };
    std::vector<Edge> edges;
    for (int i : parts[id]) {
      int x = i % w, y = i / w;
      if (!in(x, y - 1)) edges.push_back({x, y, x + 1, y, false});
      if (!in(x + 1, y)) edges.push_back({x + 1, y, x + 1, y + 1, false});
      if (!in(x, y + 1)) edges.push_back({x + 1, y + 1, x, y + 1, false});
      if (!in(x - 1, y)) edges.push_back({x, y + 1, x, y, false});
    }
    std::unordered_map<int64_t, std::vector<int>> from;
    auto key = [&](int x, int y) { return int64_t(y) * (w + 2) + x; };
    for (size_t e = 0; e < edges.size(); ++e) from[key(edges[e].x0, edges[e].y0)].push_back(static_cast<int>(e));
    std::vector<std::pair<int, int>> best;
    long best_area = -1;
    for (size_t s = 0; s < edges.size(); ++s) {
      if (edges[s].used) continue;
      std::vector<std::pair<int, int>> loop;
      int e = static_cast<int>(s);
      while (e >= 0 && !edges[e].used) {
        Edge& E = edges[e];
        E.used = true;
        loop.emplace_back(E.x0, E.y0);
        int dx = E.x1 - E.x0, dy = E.y1 - E.y0;
        int next = -1, next_rank = 9;
        for (int c : from[key(E.x1, E.y1)]) {
          if (edges[c].used) continue;
          int cx = edges[c].x1 - edges[c].x0, cy = edges[c].y1 - edges[c].y0;
          int cross = dx * cy - dy * cx;  // < 0: left turn in y-down image coordinates
          int rank = cross < 0 ? 0 : cross == 0 ? 1 : 2;
          if (rank < next_rank) { next_rank = rank; next = c; }
        }
        e = next;
      }
      long area2 = 0;
      for (size_t k = 0; k < loop.size(); ++k) {
        auto [ax, ay] = loop[k];
        auto [bx, by] = loop[(k + 1) % loop.size()];
        area2 += long(ax) * by - long(bx) * ay;
      }
      if (std::labs(area2) > best_area) { best_area = std::labs(area2); best = loop; }
    }
    // Drop collinear vertices.
    std::vector<std::pair<int, int>> simple;
    const size_t m = best.size();
    for (size_t k = 0; k < m; ++k) {
      auto [px, py] = best[(k + m - 1) % m];
      auto [cx, cy] = best[k];
      auto [nx, ny] = best[(k + 1) % m];
      if ((cx - px) * (ny - cy) - (cy - py) * (nx - cx) != 0) simple.emplace_back(cx, cy);
    }
    polys.push_back(std::move(simple));
  }
  return polys;
}

}  // namespace hgs::synth
