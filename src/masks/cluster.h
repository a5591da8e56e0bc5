// Graph of per-view masks linked by shared 3D points, and its clustering into physical objects (the core of
// `hgs masks associate`).
//
// Nodes are (view, mask) pairs. A 3D point observed in several views links the masks it falls into. Each node
// lifts only its core points (keypoints at least a margin away from the mask's boundary, chosen by the caller):
// SAM's boundary errors (masks eroded or dilated by a few pixels) put background points into a dilated mask,
// and on a small object they can outnumber the object's own. Only what the other view can see counts:
// covis(a, v) = core points of node a that view v observes (in any mask or none). The containment of a in b
// (b in view v) is c(a -> b) = |core(a) in b| / covis(a, v): the fraction of a's core points visible in v that
// fall into b. It is only tested when covis(a, v) >= max(min_points, min_covisible x |core(a)|) ("a is visible
// in v").
//
// Clustering: greedy agglomerative, best pair first, with average linkage taken in both directions:
//   C(X -> Y) = sum of c(a -> b) over a in X, b in Y with a visible in b's view / number of such pairs
//   affinity(X, Y) = sqrt(C(X -> Y) x C(Y -> X))
// Both directions must agree: a large background mask contains an object's points but its own points mostly fall
// outside the object (one direction near 0), while the same object with a thin occluder in front in some views,
// a merged neighbour or a part still has one direction near 1 and the other at 0.3-0.5. (The min of the two split
// such objects into runs of views; the max let background masks swallow objects.) Both sums and pair counts add up when
// clusters merge (pair counts = sum over views of visible_X[v] x count_Y[v]), so each merge costs O(V) per
// neighbour. A merge needs affinity >= min_affinity and is refused when both clusters hold a node of the same view
// (two masks of one view are never one object; parts of a mask are joined to it before, see associate.h). Ties
// break on the smaller cluster ids, so the result is deterministic.
//
// Parts: SAM gives an object whole and in parts; where the parts tile the whole they are folded into one node
// before (associate.h) and the node is marked `whole`, but in views where that failed (a missed or badly eroded
// whole) the parts stay separate nodes and, being two masks of one view, form clusters of their own. A cluster Y
// then joins a cluster X when Y's points lie inside X's whole nodes: mean of c(b -> a) over b in Y, a whole in X,
// b visible in a's view >= part_merge, and Y lies inside (mean >= part_merge) at least two of X's whole nodes
// and as many as an eighth of X's nodes (one stray whole in the wrong cluster must not pull an object in); best
// pair first, repeated. Two masks of one view
// end in one object only this way: one is a part of the other's object as other views show. Merged neighbours
// (label maps without parts) have no whole nodes and never join.
// Tracks (optional, MaskGraph::track: the input's ids are SAM2-style tracks, consistent across views but wrong
// in runs: a swap, a merge or a re-birth lasts many views). Before the merging above, each track's nodes are
// walked in view order (the capture order) and joined into segments: a node continues its track's current
// segment unless the 3D points measure them apart: each is visible in the other's views (pairs > 0 both ways) and
// neither contains the other, i.e. both average containments C(S -> n) and C(n -> S) are below track_split (an
// id swap); the node then starts a new segment. A merge with a neighbour, an eroded mask or a part keeps one of
// them high and stays. Without that evidence (a mask with too few points, an object seen from one side) the track's id
// is trusted. The segments then merge by affinity like single nodes, so a track re-born under a new id, or the halves
// of a swap, rejoin their object. Finally clusters seen in fewer than min_views views are dropped.
#pragma once
#include <cstdint>
#include <utility>
#include <vector>

namespace hgs::masks {

struct MaskGraph {
  int num_views = 0;
  std::vector<int> node_view;               // [N] view of each node
  std::vector<int64_t> points;              // [N] core 3D points of each node
  std::vector<std::vector<int32_t>> covis;  // [N, V] core points of the node that view v observes (0 at its own view)
  std::vector<char> whole;  // [N] optional: 1 = a whole mask whose parts were folded into it (SAM's whole + parts)
  std::vector<int> track;   // [N] optional: the node's track id (consistent-id input, e.g. SAM2), -1 = none
  // (a < b) -> (core points of a inside b, core points of b inside a), sorted by (a, b), only pairs sharing a point
  std::vector<std::pair<std::pair<int, int>, std::pair<int64_t, int64_t>>> inter;
};

// One observation of a 3D point: the view, the node of the mask it falls into (-1: no mask / a dropped mask),
// and whether it is one of that node's core points.
struct PointObservation {
  int view = 0;
  int node = -1;
  bool core = true;
};
// Builds the graph from every point's observations ([P][track]). A view listed twice for a point counts once
// (its first observation).
MaskGraph build_mask_graph(int num_views, const std::vector<int>& node_view,
                           const std::vector<std::vector<PointObservation>>& point_obs);

struct ClusterOptions {
  double min_affinity = 0.3;  // smallest two-way containment (geometric mean) to merge
  double min_covisible =
      0.25;  // a node is visible in view v when that share of its points (and min_points) is seen there
  int min_points = 3;
  int min_views = 2;         // clusters seen in fewer views are dropped
  double part_merge = 0.5;   // a cluster this contained in another's whole masks joins it as a part (0 = never)
  double track_split = 0.1;  // with MaskGraph::track: both containments below this cut the track (above)
};

struct Clustering {
  std::vector<int> cluster;  // [N] object index 0..K-1, or -1 (dropped: seen in fewer than min_views views)
  int num_objects = 0;       // K; objects ordered by views desc, then points desc, then smallest node
  std::vector<std::vector<int>> members;  // [K] nodes of each object, ascending
};

// Affinity of two node sets (exposed for tests and reports): geometric mean of the two average containments above.
double cluster_affinity(const MaskGraph& g, const std::vector<int>& x, const std::vector<int>& y,
                        const ClusterOptions& opt = {});

Clustering cluster_masks(const MaskGraph& g, const ClusterOptions& opt = {});

// For each of `nodes` (left out of the objects): the object it has the highest affinity with (as
// cluster_affinity({node}, members), computed from the node's own edges), -1 when it shares no point with any.
struct NodeMatch {
  int object = -1;
  double affinity = 0;
  bool same_view = false;  // that object already has a mask in the node's view
};
std::vector<NodeMatch> nearest_objects(const MaskGraph& g, const Clustering& c, const std::vector<int>& nodes,
                                       const ClusterOptions& opt = {});

}  // namespace hgs::masks
