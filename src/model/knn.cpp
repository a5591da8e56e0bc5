// k-d tree kNN: the tree is an index permutation; each node splits its range at the median of the axis with
// the largest extent (std::nth_element), leaves hold <= 8 points. A query descends to the nearer child first
// and visits the farther child only when the splitting plane is closer than the current k-th distance. The
// k best are kept in a small sorted array (k <= 16).
#include "model/knn.h"

#include <algorithm>
#include <limits>

#include "core/error.h"

namespace hgs {
namespace {

constexpr int kLeaf = 8;
constexpr int kMaxK = 16;

struct Node {
  int begin, end;  // range in perm
  int left = -1, right = -1;
  int axis = -1;
  float split = 0;
};

struct Tree {
  const std::vector<Eigen::Vector3f>& p;
  std::vector<int> perm;
  std::vector<Node> nodes;

  explicit Tree(const std::vector<Eigen::Vector3f>& pts) : p(pts), perm(pts.size()) {
    for (size_t i = 0; i < perm.size(); ++i) perm[i] = int(i);
    nodes.reserve(2 * (pts.size() / kLeaf + 1) + 1);
    if (!pts.empty()) build(0, int(pts.size()));
  }

  int build(int b, int e) {
    int id = int(nodes.size());
    nodes.push_back({b, e});
    if (e - b <= kLeaf) return id;
    Eigen::Vector3f lo = p[perm[b]], hi = lo;
    for (int i = b + 1; i < e; ++i) {
      lo = lo.cwiseMin(p[perm[i]]);
      hi = hi.cwiseMax(p[perm[i]]);
    }
    int axis;
    (hi - lo).maxCoeff(&axis);
    if (hi[axis] - lo[axis] <= 0) return id;  // all points identical: keep as a (big) leaf
    int m = (b + e) / 2;
    std::nth_element(perm.begin() + b, perm.begin() + m, perm.begin() + e,
                     [&](int x, int y) { return p[x][axis] < p[y][axis]; });
    float split = p[perm[m]][axis];
    int l = build(b, m);
    int r = build(m, e);
    nodes[id].left = l;
    nodes[id].right = r;
    nodes[id].axis = axis;
    nodes[id].split = split;
    return id;
  }

  struct Best {
    int k, count = 0;
    float d[kMaxK];
    int idx[kMaxK];
    float worst() const { return count < k ? std::numeric_limits<float>::infinity() : d[count - 1]; }
    void push(float dist, int i) {
      if (count == k && dist >= d[k - 1]) return;
      int j = count < k ? count++ : k - 1;
      while (j > 0 && d[j - 1] > dist) {
        d[j] = d[j - 1];
        idx[j] = idx[j - 1];
        --j;
      }
      d[j] = dist;
      idx[j] = i;
    }
  };

  void query(int node, const Eigen::Vector3f& q, int self, Best& best) const {
    const Node& nd = nodes[node];
    if (nd.left < 0) {
      for (int i = nd.begin; i < nd.end; ++i) {
        int j = perm[i];
        if (j == self) continue;
        best.push((p[j] - q).squaredNorm(), j);
      }
      return;
    }
    float diff = q[nd.axis] - nd.split;
    int near = diff < 0 ? nd.left : nd.right, far = diff < 0 ? nd.right : nd.left;
    query(near, q, self, best);
    if (diff * diff <= best.worst()) query(far, q, self, best);
  }
};

template <typename F>
void for_each_knn(const std::vector<Eigen::Vector3f>& points, int k, F&& f) {
  if (k < 1 || k > kMaxK) fail("knn: k = {} is outside 1..{}", k, kMaxK);
  Tree tree(points);
  const long n = long(points.size());
#pragma omp parallel for schedule(dynamic, 256)
  for (long i = 0; i < n; ++i) {
    Tree::Best best;
    best.k = k;
    tree.query(0, points[i], int(i), best);
    f(i, best.count, best.d, best.idx);
  }
}

}  // namespace

std::vector<float> knn_mean_sq_dist(const std::vector<Eigen::Vector3f>& points, int k) {
  std::vector<float> out(points.size(), 0.f);
  for_each_knn(points, k, [&](long i, int cnt, const float* d, const int*) {
    double s = 0;
    for (int j = 0; j < cnt; ++j) s += d[j];
    out[i] = cnt ? float(s / cnt) : 0.f;
  });
  return out;
}

std::vector<int> knn_indices(const std::vector<Eigen::Vector3f>& points, int k) {
  std::vector<int> out(points.size() * size_t(k), -1);
  for_each_knn(points, k, [&](long i, int cnt, const float*, const int* idx) {
    for (int j = 0; j < cnt; ++j) out[size_t(i) * k + j] = idx[j];
  });
  return out;
}

}  // namespace hgs
