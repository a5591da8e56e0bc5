// Mask graph and clustering (src/masks/cluster.h) on hand-made worlds: every 3D point is given the views that see
// it and the mask it falls into there, so every containment is known exactly.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>

#include <fmt/format.h>

#include "masks/cluster.h"

using namespace hgs::masks;

namespace {

// A hand-made world: named masks (nodes) in views, and points seen by given views inside given masks.
struct World {
  int views = 0;
  std::vector<int> node_view;
  std::map<std::string, int> id;
  std::vector<std::vector<PointObservation>> obs;

  std::vector<int> track;  // [N] track id of each node (-1: none); the graph gets them when any is set

  int node(const std::string& name, int view, int track_id = -1) {
    id[name] = int(node_view.size());
    node_view.push_back(view);
    track.push_back(track_id);
    return id[name];
  }
  // `n` points, each seen in every view of `seen`, inside mask `in[view]` ("" = no mask there).
  void points(int n, const std::map<int, std::string>& in) {
    for (int i = 0; i < n; ++i) {
      std::vector<PointObservation> t;
      for (auto& [v, name] : in) t.push_back({v, name.empty() ? -1 : id.at(name), true});
      obs.push_back(t);
    }
  }
  MaskGraph graph() const {
    MaskGraph g = build_mask_graph(views, node_view, obs);
    if (std::any_of(track.begin(), track.end(), [](int t) { return t >= 0; })) g.track = track;
    return g;
  }
};

// The clusters as sets of node names (dropped nodes under "-").
std::map<std::string, std::set<std::string>> named(const World& w, const Clustering& c) {
  std::map<std::string, std::set<std::string>> out;
  for (auto& [name, i] : w.id) out[c.cluster[i] < 0 ? "-" : std::to_string(c.cluster[i])].insert(name);
  return out;
}

// Two objects A, B seen by views 0..3 (each as one mask per view), plus table points no mask covers.
World two_objects(bool a_in_view2 = true) {
  World w;
  w.views = 4;
  for (int v = 0; v < 4; ++v) {
    if (v != 2 || a_in_view2) w.node(fmt::format("A{}", v), v);
    w.node(fmt::format("B{}", v), v);
  }
  return w;
}

}  // namespace

TEST(MaskGraph, CountsCoreCovisibilityAndContainmentExactly) {
  World w;
  w.views = 2;
  w.node("a", 0);
  w.node("b", 1);
  w.points(6, {{0, "a"}, {1, "b"}});  // in both masks
  w.points(2, {{0, "a"}, {1, ""}});   // a's, seen by view 1 outside b
  w.points(2, {{0, "a"}});            // a's, not seen by view 1
  w.points(3, {{0, ""}, {1, "b"}});   // b's, seen by view 0 outside a
  w.points(1, {{1, "b"}});            // b's, not seen by view 0
  // A point listed twice for one view counts once (its first observation).
  w.obs.push_back({{0, 0, true}, {0, -1, true}, {1, -1, true}});
  // A point that is not a core point of a: it does not lift a, but still counts for b as seen by view 0.
  w.obs.push_back({{0, 0, false}, {1, 1, true}});
  MaskGraph g = w.graph();
  EXPECT_EQ(g.points[0], 6 + 2 + 2 + 1);
  EXPECT_EQ(g.points[1], 6 + 3 + 1 + 1);
  EXPECT_EQ(g.covis[0][1], 6 + 2 + 1);
  EXPECT_EQ(g.covis[0][0], 0);
  EXPECT_EQ(g.covis[1][0], 6 + 3 + 1);
  ASSERT_EQ(g.inter.size(), 1u);
  EXPECT_EQ(g.inter[0].second.first, 6);       // core points of a inside b
  EXPECT_EQ(g.inter[0].second.second, 6 + 1);  // core points of b inside a (the non-core point of a is inside a)
  // c(a -> b) = 6 / 9, c(b -> a) = 7 / 10; affinity = their geometric mean.
  EXPECT_NEAR(cluster_affinity(g, {0}, {1}), std::sqrt(6.0 / 9.0 * 7.0 / 10.0), 1e-12);
  EXPECT_NEAR(cluster_affinity(g, {1}, {0}), std::sqrt(6.0 / 9.0 * 7.0 / 10.0), 1e-12);
}

TEST(MaskGraph, PairsWhereAMaskIsBarelyVisibleDoNotCount) {
  World w;
  w.views = 3;
  w.node("a", 0);
  w.node("b", 1);
  w.node("c", 2);
  w.points(20, {{0, "a"}, {1, "b"}});           // a is visible in view 1: b holds all of it
  w.points(2, {{0, "a"}, {1, "b"}, {2, "c"}});  // only 2 of a's 22 points are seen by view 2 (< 25%)
  w.points(20, {{1, "b"}});
  MaskGraph g = w.graph();
  // Neither c(a -> c) nor c(c -> a) is tested (2 points are under min_points and 25% of a): affinity 0.
  EXPECT_EQ(cluster_affinity(g, {0}, {2}), 0.0);
  // a with b: c(a -> b) = 22/22 (22 >= 25% of 22 seen), c(b -> a) = 22/22 (b's other points are not seen by view 0).
  EXPECT_NEAR(cluster_affinity(g, {0}, {1}), 1.0, 1e-12);
}

TEST(ClusterMasks, CleanObjectsGiveOneClusterEach) {
  World w = two_objects();
  w.points(40, {{0, "A0"}, {1, "A1"}, {2, "A2"}, {3, "A3"}});
  w.points(30, {{0, "B0"}, {1, "B1"}, {2, "B2"}, {3, "B3"}});
  w.points(100, {{0, ""}, {1, ""}, {2, ""}, {3, ""}});  // table
  Clustering c = cluster_masks(w.graph());
  ASSERT_EQ(c.num_objects, 2);
  // Objects are numbered by views, then points: A (160 points) before B (120).
  EXPECT_EQ(named(w, c), (std::map<std::string, std::set<std::string>>{{"0", {"A0", "A1", "A2", "A3"}},
                                                                       {"1", {"B0", "B1", "B2", "B3"}}}));
}

TEST(ClusterMasks, MissedViewLeavesTheObjectWhole) {
  World w = two_objects(/*a_in_view2=*/false);
  w.points(40, {{0, "A0"}, {1, "A1"}, {2, ""}, {3, "A3"}});  // view 2 sees A's points but has no mask for it
  w.points(30, {{0, "B0"}, {1, "B1"}, {2, "B2"}, {3, "B3"}});
  Clustering c = cluster_masks(w.graph());
  // B is seen in 4 views, A in 3: B first.
  EXPECT_EQ(named(w, c),
            (std::map<std::string, std::set<std::string>>{{"0", {"B0", "B1", "B2", "B3"}}, {"1", {"A0", "A1", "A3"}}}));
}

TEST(ClusterMasks, SplitObjectKeepsItsLargerPartAndNeverTwoMasksOfOneView) {
  World w;
  w.views = 4;
  for (int v : {0, 1, 3}) w.node(fmt::format("A{}", v), v);
  w.node("a2_big", 2);
  w.node("a2_small", 2);
  w.points(24, {{0, "A0"}, {1, "A1"}, {2, "a2_big"}, {3, "A3"}});
  w.points(16, {{0, "A0"}, {1, "A1"}, {2, "a2_small"}, {3, "A3"}});
  w.points(50, {{0, ""}, {1, ""}, {2, ""}, {3, ""}});
  MaskGraph g = w.graph();
  // The parts are fully inside A (c = 1) and hold 60% / 40% of A's points seen by view 2.
  EXPECT_NEAR(cluster_affinity(g, {w.id["a2_big"]}, {w.id["A0"], w.id["A1"], w.id["A3"]}), std::sqrt(0.6), 1e-12);
  EXPECT_NEAR(cluster_affinity(g, {w.id["a2_small"]}, {w.id["A0"], w.id["A1"], w.id["A3"]}), std::sqrt(0.4), 1e-12);
  Clustering c = cluster_masks(g);
  EXPECT_EQ(named(w, c),
            (std::map<std::string, std::set<std::string>>{{"0", {"A0", "A1", "A3", "a2_big"}}, {"-", {"a2_small"}}}));
}

TEST(ClusterMasks, MergedPairJoinsTheObjectItMostlyHolds) {
  World w;
  w.views = 4;
  for (int v : {0, 1, 3}) w.node(fmt::format("A{}", v), v), w.node(fmt::format("B{}", v), v);
  w.node("AB2", 2);  // SAM merged the touching A and B in view 2
  w.points(36, {{0, "A0"}, {1, "A1"}, {2, "AB2"}, {3, "A3"}});
  w.points(24, {{0, "B0"}, {1, "B1"}, {2, "AB2"}, {3, "B3"}});
  w.points(80, {{0, ""}, {1, ""}, {2, ""}, {3, ""}});
  Clustering c = cluster_masks(w.graph());
  EXPECT_EQ(named(w, c), (std::map<std::string, std::set<std::string>>{{"0", {"A0", "A1", "A3", "AB2"}},
                                                                       {"1", {"B0", "B1", "B3"}}}));
}

TEST(ClusterMasks, BackgroundMaskHoldingAnObjectStaysOut) {
  World w;
  w.views = 4;
  for (int v : {0, 2, 3}) w.node(fmt::format("A{}", v), v);
  w.node("G1", 1);  // a large mask in view 1 (A missed there) over A and the table around it
  w.points(20, {{0, "A0"}, {1, "G1"}, {2, "A2"}, {3, "A3"}});
  w.points(300, {{0, ""}, {1, "G1"}, {2, ""}, {3, ""}});
  MaskGraph g = w.graph();
  // A's points all fall in G1, but only 20 of G1's 320 fall in A: sqrt(1 x 20/320) < 0.3.
  EXPECT_NEAR(cluster_affinity(g, {w.id["G1"]}, {w.id["A0"], w.id["A2"], w.id["A3"]}), std::sqrt(20.0 / 320.0), 1e-12);
  Clustering c = cluster_masks(g);
  EXPECT_EQ(named(w, c), (std::map<std::string, std::set<std::string>>{{"0", {"A0", "A2", "A3"}}, {"-", {"G1"}}}));
  // With min_views 1 the background mask is an object of its own, after A.
  ClusterOptions o;
  o.min_views = 1;
  c = cluster_masks(g, o);
  EXPECT_EQ(named(w, c), (std::map<std::string, std::set<std::string>>{{"0", {"A0", "A2", "A3"}}, {"1", {"G1"}}}));
}

TEST(ClusterMasks, ThresholdDecides) {
  World w;
  w.views = 2;
  w.node("a", 0);
  w.node("b", 1);
  w.points(10, {{0, "a"}, {1, "b"}});
  w.points(30, {{0, "a"}, {1, ""}});  // c(a -> b) = 0.25, c(b -> a) = 1: affinity 0.5
  MaskGraph g = w.graph();
  ClusterOptions o;
  o.min_views = 1;
  o.min_affinity = 0.49;
  EXPECT_EQ(cluster_masks(g, o).num_objects, 1);
  o.min_affinity = 0.51;
  EXPECT_EQ(cluster_masks(g, o).num_objects, 2);
}

TEST(ClusterMasks, RandomGraphsNeverPutTwoMasksOfOneViewTogetherAndAreDeterministic) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 60; ++trial) {
    World w;
    w.views = 6;
    const int per_view = 1 + int(rng() % 5);
    // Odd trials: random track ids (MaskGraph::track), a track sometimes twice in one view.
    for (int v = 0; v < w.views; ++v)
      for (int m = 0; m < per_view; ++m)
        w.node(std::to_string(v) + "_" + std::to_string(m), v, trial % 2 ? int(rng() % (per_view + 1)) - 1 : -1);
    for (int p = 0; p < 300; ++p) {  // each point: random views, random masks (often none)
      std::map<int, std::string> in;
      for (int v = 0; v < w.views; ++v)
        if (rng() % 2) in[v] = rng() % 3 ? std::to_string(v) + "_" + std::to_string(rng() % per_view) : "";
      w.points(1, in);
    }
    MaskGraph g = w.graph();
    ClusterOptions o;
    o.min_affinity = 0.05;  // merge eagerly: only the cannot-link holds things apart
    o.min_views = 1;
    Clustering c = cluster_masks(g, o);
    for (auto& m : c.members) {
      std::set<int> views;
      for (int n : m) EXPECT_TRUE(views.insert(g.node_view[n]).second) << "trial " << trial;
    }
    EXPECT_EQ(c.cluster, cluster_masks(g, o).cluster);
  }
}

TEST(ClusterMasks, PartsKeptApartInSomeViewsJoinTheObjectWhoseWholesHoldThem) {
  // Views 0, 1: SAM's whole A (its parts folded into it: `whole`); views 2, 3: the two halves apart (the whole
  // missed), so each half forms a cluster of its own, never with the other (same views).
  World w;
  w.views = 4;
  w.node("W0", 0);
  w.node("W1", 1);
  for (int v : {2, 3}) w.node(fmt::format("L{}", v), v), w.node(fmt::format("R{}", v), v);
  w.node("B0", 0);  // a neighbour, never inside A's wholes
  w.node("B2", 2);
  w.points(20, {{0, "W0"}, {1, "W1"}, {2, "L2"}, {3, "L3"}});
  w.points(20, {{0, "W0"}, {1, "W1"}, {2, "R2"}, {3, "R3"}});
  w.points(15, {{0, "B0"}, {1, ""}, {2, "B2"}});
  w.points(60, {{0, ""}, {1, ""}, {2, ""}, {3, ""}});
  MaskGraph g = w.graph();
  ClusterOptions o;
  o.part_merge = 0;
  EXPECT_EQ(named(w, cluster_masks(g, o)),
            (std::map<std::string, std::set<std::string>>{{"0", {"L2", "L3", "W0", "W1"}},
                                                          {"1", {"R2", "R3"}},
                                                          {"2", {"B0", "B2"}}}));
  // Without whole marks nothing joins either (merged neighbours look the same).
  EXPECT_EQ(named(w, cluster_masks(g)), named(w, cluster_masks(g, o)));
  g.whole.assign(g.node_view.size(), 0);
  g.whole[w.id["W0"]] = g.whole[w.id["W1"]] = 1;
  EXPECT_EQ(named(w, cluster_masks(g)),
            (std::map<std::string, std::set<std::string>>{{"0", {"L2", "L3", "R2", "R3", "W0", "W1"}},
                                                          {"1", {"B0", "B2"}}}));
}

TEST(ClusterMasks, NearestObjectsAgreeWithTheAffinityOfEachObject) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 10; ++trial) {
    World w;
    w.views = 5;
    for (int v = 0; v < w.views; ++v)
      for (int m = 0; m < 4; ++m) w.node(std::to_string(v) + "_" + std::to_string(m), v);
    for (int p = 0; p < 400; ++p) {
      std::map<int, std::string> in;
      for (int v = 0; v < w.views; ++v)
        if (rng() % 2) in[v] = rng() % 4 ? std::to_string(v) + "_" + std::to_string(rng() % 4) : "";
      w.points(1, in);
    }
    MaskGraph g = w.graph();
    ClusterOptions o;
    o.min_affinity = 0.2;
    Clustering c = cluster_masks(g, o);
    std::vector<int> nodes(g.node_view.size());
    for (size_t i = 0; i < nodes.size(); ++i) nodes[i] = int(i);
    const std::vector<NodeMatch> near = nearest_objects(g, c, nodes, o);
    for (int n : nodes) {  // brute force over the objects
      double best = 0;
      int best_k = -1;
      for (int k = 0; k < c.num_objects; ++k) {
        const double a = cluster_affinity(g, {n}, c.members[k], o);
        if (a > best) best = a, best_k = k;
      }
      EXPECT_NEAR(near[n].affinity, best, 1e-12) << trial << " " << n;
      if (best > 0) {
        EXPECT_EQ(near[n].object, best_k) << trial << " " << n;
      }
    }
  }
}

// Tracks (MaskGraph::track, SAM2-style ids): the two tracks of A and B swap ids at view 3 and stay swapped.
TEST(ClusterTracks, AnIdSwapCutsBothTracksAndTheHalvesRejoinTheirObjects) {
  World w;
  w.views = 6;
  for (int v = 0; v < 6; ++v) w.node(fmt::format("t1_{}", v), v, 1), w.node(fmt::format("t2_{}", v), v, 2);
  w.points(40, {{0, "t1_0"}, {1, "t1_1"}, {2, "t1_2"}, {3, "t2_3"}, {4, "t2_4"}, {5, "t2_5"}});  // A
  w.points(30, {{0, "t2_0"}, {1, "t2_1"}, {2, "t2_2"}, {3, "t1_3"}, {4, "t1_4"}, {5, "t1_5"}});  // B
  w.points(60, {{0, ""}, {1, ""}, {2, ""}, {3, ""}, {4, ""}, {5, ""}});
  MaskGraph g = w.graph();
  const std::map<std::string, std::set<std::string>> objects{{"0", {"t1_0", "t1_1", "t1_2", "t2_3", "t2_4", "t2_5"}},
                                                             {"1", {"t2_0", "t2_1", "t2_2", "t1_3", "t1_4", "t1_5"}}};
  EXPECT_EQ(named(w, cluster_masks(g)), objects);
  // Never cutting a track (split 0) keeps the swapped ids: each object is then half of A and half of B.
  ClusterOptions keep;
  keep.track_split = 0;
  EXPECT_EQ(named(w, cluster_masks(g, keep)),
            (std::map<std::string, std::set<std::string>>{{"0", {"t1_0", "t1_1", "t1_2", "t1_3", "t1_4", "t1_5"}},
                                                          {"1", {"t2_0", "t2_1", "t2_2", "t2_3", "t2_4", "t2_5"}}}));
}

// Where the points say nothing or little, the track's id is kept; where they measure the masks apart, it is cut.
TEST(ClusterTracks, AMaskWithoutEvidenceRidesItsTrackAndTheSplitThresholdDecides) {
  World w;
  w.views = 5;
  for (int v = 0; v < 5; ++v) w.node(fmt::format("A{}", v), v);
  // A is seen from two sides: 10 points in its masks in every view, 40 only in views 0-1 (views 2-3 see them
  // outside any mask: an occluder), 40 only in views 2-3. A4 holds no point at all (too small to lift).
  w.points(10, {{0, "A0"}, {1, "A1"}, {2, "A2"}, {3, "A3"}});
  w.points(40, {{0, "A0"}, {1, "A1"}, {2, ""}, {3, ""}});
  w.points(40, {{0, ""}, {1, ""}, {2, "A2"}, {3, "A3"}});
  MaskGraph g = w.graph();
  // The two sides' masks contain a fifth of each other's points visible to them.
  EXPECT_NEAR(cluster_affinity(g, {w.id["A0"], w.id["A1"]}, {w.id["A2"], w.id["A3"]}), 0.2, 1e-12);
  // Without tracks: two objects (0.2 < min_affinity 0.3), and A4, which shares no point, is dropped.
  EXPECT_EQ(named(w, cluster_masks(g)),
            (std::map<std::string, std::set<std::string>>{{"0", {"A0", "A1"}}, {"1", {"A2", "A3"}}, {"-", {"A4"}}}));
  g.track.assign(5, 7);
  ClusterOptions split;
  split.track_split = 0.1;  // 0.2 is not "apart": one object, A4 riding along
  EXPECT_EQ(named(w, cluster_masks(g, split)),
            (std::map<std::string, std::set<std::string>>{{"0", {"A0", "A1", "A2", "A3", "A4"}}}));
  split.track_split = 0.3;  // apart: the track is cut at view 2, and A4 stays with the second segment
  EXPECT_EQ(named(w, cluster_masks(g, split)),
            (std::map<std::string, std::set<std::string>>{{"0", {"A2", "A3", "A4"}}, {"1", {"A0", "A1"}}}));
}

// SAM2 merges two touching objects under one id while they touch: the merged masks contain the track's object,
// so the track is not cut there, even though the merged mask is mostly the other object.
TEST(ClusterTracks, AMergeWithALargeNeighbourStaysOnItsTrack) {
  World w;
  w.views = 6;
  for (int v = 0; v < 6; ++v) {
    w.node(fmt::format("A{}", v), v, 1);
    if (v < 3) w.node(fmt::format("B{}", v), v, 2);  // B's track is lost while merged into A's
  }
  w.points(10, {{0, "A0"}, {1, "A1"}, {2, "A2"}, {3, "A3"}, {4, "A4"}, {5, "A5"}});
  w.points(400, {{0, "B0"}, {1, "B1"}, {2, "B2"}, {3, "A3"}, {4, "A4"}, {5, "A5"}});  // A3-A5: A and B merged
  MaskGraph g = w.graph();
  // From view 3 on, A's masks hold all of A's points (C(S -> n) = 1) but A's points are 10 of their 410.
  EXPECT_LT(cluster_affinity(g, {w.id["A0"], w.id["A1"], w.id["A2"]}, {w.id["A3"]}), 0.2);
  Clustering c = cluster_masks(g);
  EXPECT_EQ(c.cluster[w.id["A3"]], c.cluster[w.id["A0"]]);
  EXPECT_EQ(c.cluster[w.id["A5"]], c.cluster[w.id["A0"]]);
  EXPECT_NE(c.cluster[w.id["B0"]], c.cluster[w.id["A0"]]);
}
