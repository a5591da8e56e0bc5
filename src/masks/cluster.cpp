// Mask graph and its greedy two-way average-containment clustering with same-view cannot-links (cluster.h).
#include "masks/cluster.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <queue>
#include <tuple>
#include <unordered_map>

namespace hgs::masks {

MaskGraph build_mask_graph(int num_views, const std::vector<int>& node_view,
                           const std::vector<std::vector<PointObservation>>& point_obs) {
  MaskGraph g;
  g.num_views = num_views;
  g.node_view = node_view;
  const size_t N = node_view.size();
  g.points.assign(N, 0);
  g.covis.assign(N, std::vector<int32_t>(size_t(num_views), 0));
  std::unordered_map<uint64_t, std::pair<int64_t, int64_t>> inter;
  std::vector<PointObservation> obs;
  std::vector<char> seen(size_t(num_views), 0);
  for (const auto& track : point_obs) {
    obs.clear();
    for (const auto& o : track)  // first observation per view
      if (!seen[o.view]) seen[o.view] = 1, obs.push_back(o);
    for (const auto& o : obs) seen[o.view] = 0;
    for (size_t i = 0; i < obs.size(); ++i) {
      const int a = obs[i].node;
      if (a < 0 || !obs[i].core) continue;
      ++g.points[a];
      for (size_t j = 0; j < obs.size(); ++j) {
        if (j == i) continue;
        ++g.covis[a][obs[j].view];
        const int b = obs[j].node;
        if (b < 0) continue;
        if (a < b) ++inter[(uint64_t(a) << 32) | uint64_t(b)].first;
        else ++inter[(uint64_t(b) << 32) | uint64_t(a)].second;
      }
    }
  }
  g.inter.reserve(inter.size());
  for (auto& [k, n] : inter) g.inter.push_back({{int(k >> 32), int(k & 0xffffffffu)}, n});
  std::sort(g.inter.begin(), g.inter.end());
  return g;
}

namespace {

struct Cluster {
  std::vector<int64_t> count, visible;           // [V] nodes in view v, nodes visible in view v
  std::map<int, std::pair<double, double>> nbr;  // other cluster -> (sum c(this -> other), sum c(other -> this))
  std::vector<int> nodes;
  int stamp = 0;
  bool alive = true;
};

bool visible_in(const MaskGraph& g, int a, int v, const ClusterOptions& opt) {
  const int64_t c = g.covis[a][v];
  return c > 0 && c >= opt.min_points && double(c) >= opt.min_covisible * double(g.points[a]);
}

// The average containments C(X -> Y) = s.first / pairs_xy and C(Y -> X) = s.second / pairs_yx, where pairs_xy
// counts (a in X, b in Y) with a visible in b's view. `measured`: both directions have pairs.
struct Containments {
  double xy = 0, yx = 0;
  bool measured = false;
};
Containments containments(const Cluster& x, const Cluster& y, const std::pair<double, double>& s) {
  double pxy = 0, pyx = 0;
  for (size_t v = 0; v < x.count.size(); ++v)
    pxy += double(x.visible[v]) * double(y.count[v]), pyx += double(y.visible[v]) * double(x.count[v]);
  if (pxy <= 0 || pyx <= 0) return {};
  return {s.first / pxy, s.second / pyx, true};
}

double affinity(const Cluster& x, const Cluster& y, const std::pair<double, double>& s) {
  const Containments c = containments(x, y, s);
  return c.measured ? std::sqrt(c.xy * c.yx) : 0;
}

bool share_a_view(const Cluster& x, const Cluster& y) {
  for (size_t v = 0; v < x.count.size(); ++v)
    if (x.count[v] && y.count[v]) return true;
  return false;
}

Cluster make_cluster(const MaskGraph& g, const std::vector<int>& nodes, const ClusterOptions& opt) {
  Cluster c;
  c.count.assign(size_t(g.num_views), 0);
  c.visible.assign(size_t(g.num_views), 0);
  for (int a : nodes) {
    ++c.count[g.node_view[a]];
    for (int v = 0; v < g.num_views; ++v) c.visible[v] += visible_in(g, a, v, opt);
  }
  c.nodes = nodes;
  return c;
}

// c(a -> b) given `inter` core points of a inside b (0 when a is not visible in b's view).
double containment(const MaskGraph& g, int a, int b, int64_t inter, const ClusterOptions& opt) {
  const int v = g.node_view[b];
  return visible_in(g, a, v, opt) ? double(inter) / double(g.covis[a][v]) : 0.0;
}

}  // namespace

double cluster_affinity(const MaskGraph& g, const std::vector<int>& x, const std::vector<int>& y,
                        const ClusterOptions& opt) {
  std::vector<char> in_x(g.node_view.size(), 0), in_y(g.node_view.size(), 0);
  for (int a : x) in_x[a] = 1;
  for (int b : y) in_y[b] = 1;
  std::pair<double, double> s{0, 0};
  for (auto& [ab, n] : g.inter) {
    auto [a, b] = ab;
    auto [nab, nba] = n;
    if (in_y[a] && in_x[b]) std::swap(a, b), std::swap(nab, nba);
    else if (!(in_x[a] && in_y[b])) continue;
    s.first += containment(g, a, b, nab, opt);
    s.second += containment(g, b, a, nba, opt);
  }
  return affinity(make_cluster(g, x, opt), make_cluster(g, y, opt), s);
}

namespace {

// Every node a cluster of its own, with the containment sums of its neighbours.
std::vector<Cluster> single_node_clusters(const MaskGraph& g, const ClusterOptions& opt) {
  const int N = int(g.node_view.size());
  std::vector<Cluster> cl(static_cast<size_t>(N));
  for (int a = 0; a < N; ++a) cl[a] = make_cluster(g, {a}, opt);
  for (auto& [ab, n] : g.inter) {
    const auto [a, b] = ab;
    const double sab = containment(g, a, b, n.first, opt), sba = containment(g, b, a, n.second, opt);
    cl[a].nbr[b] = {sab, sba};
    cl[b].nbr[a] = {sba, sab};
  }
  return cl;
}

// Merges cluster b into cluster a (counts, nodes, neighbour sums).
void merge(const MaskGraph& g, std::vector<Cluster>& cl, int a, int b) {
  Cluster& A = cl[a];
  Cluster& B = cl[b];
  for (int v = 0; v < g.num_views; ++v) A.count[v] += B.count[v], A.visible[v] += B.visible[v];
  A.nodes.insert(A.nodes.end(), B.nodes.begin(), B.nodes.end());
  for (auto& [c, xy] : B.nbr) {
    if (c == a) continue;
    auto& ac = A.nbr[c];
    ac.first += xy.first, ac.second += xy.second;
    cl[c].nbr.erase(b);
    auto& ca = cl[c].nbr[a];
    ca.first += xy.second, ca.second += xy.first;
  }
  A.nbr.erase(b);
  B.nbr.clear();
  B.alive = false;
  ++A.stamp;
}

// Greedy: the pair of clusters with the highest affinity (>= min_affinity, no view in common) merges first.
void merge_by_affinity(const MaskGraph& g, const ClusterOptions& opt, std::vector<Cluster>& cl) {
  // Max-heap on affinity; equal affinities: smaller (a, b) first.
  using Item = std::tuple<double, int, int, int, int>;  // affinity, a, b, stamp a, stamp b
  auto worse = [](const Item& p, const Item& q) {
    if (std::get<0>(p) != std::get<0>(q)) return std::get<0>(p) < std::get<0>(q);
    return std::make_pair(std::get<1>(p), std::get<2>(p)) > std::make_pair(std::get<1>(q), std::get<2>(q));
  };
  std::priority_queue<Item, std::vector<Item>, decltype(worse)> heap(worse);
  auto push = [&](int a, int b) {
    if (a > b) std::swap(a, b);
    const double s = affinity(cl[a], cl[b], cl[a].nbr.at(b));
    if (s >= opt.min_affinity && !share_a_view(cl[a], cl[b])) heap.emplace(s, a, b, cl[a].stamp, cl[b].stamp);
  };
  for (int a = 0; a < int(cl.size()); ++a)
    for (auto& [b, n] : cl[a].nbr)
      if (b > a) push(a, b);
  while (!heap.empty()) {
    auto [s, a, b, sa, sb] = heap.top();
    heap.pop();
    if (!cl[a].alive || !cl[b].alive || cl[a].stamp != sa || cl[b].stamp != sb) continue;
    if (share_a_view(cl[a], cl[b])) continue;
    merge(g, cl, a, b);
    for (auto& [c, xy] : cl[a].nbr) push(a, c);
  }
}

// Tracks: each track's nodes, in view order, join its current segment unless measured apart (cluster.h).
void follow_tracks(const MaskGraph& g, const ClusterOptions& opt, std::vector<Cluster>& cl) {
  std::map<int, std::vector<int>> tracks;  // track id -> nodes
  for (int a = 0; a < int(g.track.size()); ++a)
    if (g.track[a] >= 0) tracks[g.track[a]].push_back(a);
  for (auto& [id, nodes] : tracks) {
    std::stable_sort(nodes.begin(), nodes.end(), [&](int a, int b) { return g.node_view[a] < g.node_view[b]; });
    int seg = nodes.front();
    for (size_t i = 1; i < nodes.size(); ++i) {
      const int n = nodes[i];
      const Cluster &S = cl[seg], &N = cl[n];
      // Apart: neither contains the other. A merge with a neighbour, an eroded mask or a part keeps one of the
      // two average containments high; another object (an id swap) has both near 0.
      auto it = S.nbr.find(n);
      const Containments c = containments(S, N, it == S.nbr.end() ? std::pair<double, double>{0, 0} : it->second);
      const bool apart = c.measured && std::max(c.xy, c.yx) < opt.track_split;
      if (apart || share_a_view(S, N)) seg = n;
      else merge(g, cl, seg, n);
    }
  }
}

// What part merging reads: the core points of each node inside each other node.
struct PartContext {
  const MaskGraph& g;
  const ClusterOptions& opt;
  const std::vector<Cluster>& cl;
  std::unordered_map<uint64_t, int64_t> core_in;  // (a, b) -> core points of a inside b

  int wholes(int x) const {
    int n = 0;
    for (int a : cl[x].nodes) n += g.whole[a];
    return n;
  }

  // Mean containment of y in x's whole nodes, or -1 when y does not lie inside enough of them.
  double part_score(int x, int y) const {
    double sum = 0;
    int pairs = 0, holding = 0;  // holding: whole nodes of x that hold y on average
    for (int a : cl[x].nodes) {
      if (!g.whole[a]) continue;
      double sa = 0;
      int pa = 0;
      for (int b : cl[y].nodes) {
        if (!visible_in(g, b, g.node_view[a], opt)) continue;
        ++pa;
        auto it = core_in.find((uint64_t(b) << 32) | uint64_t(a));
        if (it != core_in.end()) sa += containment(g, b, a, it->second, opt);
      }
      sum += sa, pairs += pa;
      holding += pa > 0 && sa >= opt.part_merge * pa;
    }
    // A stray whole mask clustered into the wrong object must not pull another object in: the parts must
    // lie inside at least two of x's wholes and an eighth of x's masks.
    if (pairs < 2 || holding < 2 || 8 * holding < int(cl[x].nodes.size())) return -1;
    return sum / pairs;
  }
};

// Parts: a cluster whose points lie inside another cluster's whole masks (nodes that parts were folded into)
// is a part of that object that SAM kept apart in some views; best pair first.
void merge_parts(const MaskGraph& g, const ClusterOptions& opt, std::vector<Cluster>& cl) {
  PartContext pc{g, opt, cl, {}};
  for (auto& [ab, n] : g.inter) {
    pc.core_in[(uint64_t(ab.first) << 32) | uint64_t(ab.second)] = n.first;
    pc.core_in[(uint64_t(ab.second) << 32) | uint64_t(ab.first)] = n.second;
  }
  std::map<std::pair<int, int>, double> score;  // (x, y): y would join x; only neighbours sharing points
  auto rescore = [&](int x, int y) {
    const double c = pc.wholes(x) >= 2 ? pc.part_score(x, y) : -1;
    if (c >= opt.part_merge) score[{x, y}] = c;
    else score.erase({x, y});
  };
  for (int x = 0; x < int(cl.size()); ++x)
    if (cl[x].alive && pc.wholes(x) >= 2)
      for (auto& [y, xy] : cl[x].nbr) rescore(x, y);
  while (!score.empty()) {
    auto best = score.begin();
    for (auto it = score.begin(); it != score.end(); ++it)
      if (it->second > best->second) best = it;  // ties: the smallest (x, y)
    const auto [x, y] = best->first;
    merge(g, cl, x, y);
    for (auto it = score.begin(); it != score.end();)
      it = it->first.first == x || it->first.second == x || it->first.first == y || it->first.second == y
               ? score.erase(it)
               : std::next(it);
    for (auto& [c, xy] : cl[x].nbr) {
      rescore(x, c);
      rescore(c, x);
    }
  }
}

// Objects: clusters seen in at least min_views views, ordered by views, points, first node.
Clustering number_objects(const MaskGraph& g, const ClusterOptions& opt, const std::vector<Cluster>& cl) {
  struct Obj {
    int views;
    int64_t points;
    std::vector<int> nodes;
  };
  std::vector<Obj> objs;
  for (size_t a = 0; a < cl.size(); ++a) {
    if (!cl[a].alive) continue;
    int views = 0;
    for (int64_t c : cl[a].count) views += c > 0;
    if (views < opt.min_views) continue;
    int64_t pts = 0;
    for (int n : cl[a].nodes) pts += g.points[n];
    std::vector<int> nodes = cl[a].nodes;
    std::sort(nodes.begin(), nodes.end());
    objs.push_back({views, pts, std::move(nodes)});
  }
  std::sort(objs.begin(), objs.end(), [](const Obj& p, const Obj& q) {
    if (p.views != q.views) return p.views > q.views;
    if (p.points != q.points) return p.points > q.points;
    return p.nodes.front() < q.nodes.front();
  });
  Clustering r;
  r.cluster.assign(cl.size(), -1);
  r.num_objects = int(objs.size());
  for (int k = 0; k < r.num_objects; ++k) {
    for (int n : objs[k].nodes) r.cluster[n] = k;
    r.members.push_back(std::move(objs[k].nodes));
  }
  return r;
}

}  // namespace

Clustering cluster_masks(const MaskGraph& g, const ClusterOptions& opt) {
  std::vector<Cluster> cl = single_node_clusters(g, opt);
  if (!g.track.empty()) follow_tracks(g, opt, cl);
  merge_by_affinity(g, opt, cl);
  if (opt.part_merge > 0 && !g.whole.empty()) merge_parts(g, opt, cl);
  return number_objects(g, opt, cl);
}

std::vector<NodeMatch> nearest_objects(const MaskGraph& g, const Clustering& c, const std::vector<int>& nodes,
                                       const ClusterOptions& opt) {
  const int K = c.num_objects, V = g.num_views;
  std::vector<std::vector<int64_t>> count(size_t(K), std::vector<int64_t>(size_t(V), 0)), visible = count;  // [K, V]
  for (int k = 0; k < K; ++k)
    for (int a : c.members[k]) {
      ++count[k][g.node_view[a]];
      for (int v = 0; v < V; ++v) visible[k][v] += visible_in(g, a, v, opt);
    }
  std::vector<char> wanted(g.node_view.size(), 0);
  for (int n : nodes) wanted[n] = 1;
  std::vector<std::map<int, std::pair<double, double>>> sums(
      g.node_view.size());  // node -> object -> (c(n->o), c(o->n))
  for (auto& [ab, n] : g.inter) {
    const auto [a, b] = ab;
    if (wanted[a] && c.cluster[b] >= 0) {
      auto& s = sums[a][c.cluster[b]];
      s.first += containment(g, a, b, n.first, opt), s.second += containment(g, b, a, n.second, opt);
    }
    if (wanted[b] && c.cluster[a] >= 0) {
      auto& s = sums[b][c.cluster[a]];
      s.first += containment(g, b, a, n.second, opt), s.second += containment(g, a, b, n.first, opt);
    }
  }
  std::vector<NodeMatch> out;
  for (int n : nodes) {
    NodeMatch m;
    for (auto& [k, s] : sums[n]) {
      double pno = 0;
      for (int v = 0; v < V; ++v) pno += double(visible_in(g, n, v, opt)) * double(count[k][v]);
      const double pon = double(visible[k][g.node_view[n]]);
      const double aff = pno > 0 && pon > 0 ? std::sqrt((s.first / pno) * (s.second / pon)) : 0;
      if (m.object < 0 || aff > m.affinity) m.object = k, m.affinity = aff;
    }
    if (m.object >= 0) m.same_view = count[m.object][g.node_view[n]] > 0;
    out.push_back(m);
  }
  return out;
}

}  // namespace hgs::masks
