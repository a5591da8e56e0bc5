// Association driver (steps in associate.h): read the per-view masks and COLMAP's keypoint -> 3D point table,
// make (view, mask) nodes, cluster them (cluster.h), name and number the objects, write the consistent label maps
// and the report into a temporary folder and swap it in. Each phase is one function below, called in order by
// associate_masks at the end of the file.
#include "masks/associate.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <unordered_map>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/json_file.h"
#include "core/npy.h"
#include "core/progress.h"
#include "masks/cluster.h"
#include "masks/depth_tracks.h"
#include "masks/flatten.h"
#include "masks/per_view.h"
#include "masks/sources.h"
#include "scene/colmap.h"
#include "scene/scene.h"

namespace hgs::masks {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

bool non_empty_dir(const fs::path& d) { return fs::is_directory(d) && !fs::is_empty(d); }

struct Node {
  int view = 0;
  int label = 0;            // root id in the per-view map
  long area = 0;            // pixels
  std::vector<int> points;  // dense point indices inside the mask
  std::string drop;         // reason when dropped before clustering
  std::vector<int> ids;     // per-view ids folded into it (itself first)
};

std::string most_common(const std::vector<std::string>& names) {
  std::map<std::string, int> count;
  for (auto& n : names) ++count[n];
  std::string best;
  int bc = 0;
  for (auto& [n, c] : count)
    if (c > bc) best = n, bc = c;  // map order: ties go to the alphabetically first
  return best;
}

// ---- Phase 1: options, folders, correspondences, names ----

void check_options(const AssociateOptions& opt) {
  if (opt.min_views < 1) fail("--min-views: must be at least 1, got {}", opt.min_views);
  if (opt.min_points < 1) fail("--min-points: must be at least 1, got {}", opt.min_points);
  if (!(opt.max_area > 0 && opt.max_area <= 1)) fail("--max-area: must be in (0, 1], got {}", opt.max_area);
  if (!(opt.min_affinity > 0 && opt.min_affinity <= 1))
    fail("--min-affinity: must be in (0, 1], got {}", opt.min_affinity);
  if (!(opt.track_split >= 0 && opt.track_split <= 1))
    fail("--track-split: must be in [0, 1], got {}", opt.track_split);
}

// Where the per-view masks are read from and where the associated ones go.
struct Folders {
  fs::path masks_dir;       // SCENE/masks
  fs::path in;              // the per-view input: masks/, or masks/per_view/ once associated
  bool associated = false;  // masks/associate.json exists
  bool in_place = false;    // no --out-masks: the result replaces masks/
};

Folders find_folders(const AssociateOptions& opt, const Scene& s) {
  Folders f;
  f.masks_dir = s.root / "masks";
  f.associated = fs::exists(f.masks_dir / "associate.json");
  f.in_place = opt.out_masks.empty();
  if (f.associated && f.in_place && !opt.force)
    fail("{}: masks are already associated (associate.json); pass --force to associate again from masks/per_view",
         f.masks_dir.string());
  f.in = f.associated ? f.masks_dir / "per_view" : f.masks_dir;
  if (!fs::is_directory(f.in))
    fail("{}: no masks folder (per-view masks/<stem>.png, e.g. from `hgs masks import`)", f.in.string());
  if (f.associated && !fs::is_directory(f.in))
    fail("{}: associate.json but no per_view/ folder with the original masks", f.masks_dir.string());
  if (!f.in_place && !opt.force && non_empty_dir(opt.out_masks))
    fail("{}: already exists and is not empty; pass --force to replace it", opt.out_masks.string());
  return f;
}

// COLMAP's 2D-3D correspondences: the 3D point each keypoint of each image observes.
struct Correspondences {
  ColmapModel model;
  fs::path model_dir, images_file;
  std::unordered_map<int64_t, int> point_index;  // COLMAP point id -> index into model.points
  std::map<int, int> image_index;                // COLMAP image id -> index into model.images
};

Correspondences read_correspondences(const Scene& s) {
  Correspondences cc;
  cc.model_dir = colmap_model_dir(s.root);
  cc.model = read_colmap(cc.model_dir);
  cc.images_file = cc.model_dir / (fs::exists(cc.model_dir / "images.bin") ? "images.bin" : "images.txt");
  for (size_t i = 0; i < cc.model.points.size(); ++i) cc.point_index[int64_t(cc.model.points[i].id)] = int(i);
  size_t observed = 0;
  for (size_t i = 0; i < cc.model.images.size(); ++i) {
    const ColmapImage& im = cc.model.images[i];
    cc.image_index[im.id] = int(i);
    for (int64_t p : im.point3d_ids) observed += p >= 0 && cc.point_index.count(p);
  }
  if (observed == 0)
    fail(
        "{}: no keypoint observes a 3D point (the model has no 2D-3D correspondences; run COLMAP's mapper or "
        "point_triangulator)",
        cc.images_file.string());
  return cc;
}

// What the input says about its masks besides the label maps: names and the import record.
struct InputInfo {
  json names_file;                          // --names: {"<stem>": {"<id>": "name"}}, or null
  std::map<int, std::string> global_names;  // objects.json of the input: the same id in every view
  json import_info;                         // import.json of the input, or null
  bool sam_scores = false;                  // imported from SAM's files: one score per mask
};

InputInfo read_input_info(const AssociateOptions& opt, const fs::path& in) {
  InputInfo ii;
  ii.names_file = opt.names.empty() ? json() : read_json_file(opt.names);
  if (!opt.names.empty() && !ii.names_file.is_object())
    fail("{}: expected {{\"<stem>\": {{\"<id>\": \"name\"}}}}", opt.names.string());
  if (fs::exists(in / "objects.json")) {
    json j = read_json_file(in / "objects.json");
    if (!j.is_object()) fail("{}: expected {{\"<id>\": \"name\"}}", (in / "objects.json").string());
    for (auto& [k, v] : j.items())
      if (v.is_string()) ii.global_names[std::atoi(k.c_str())] = v.get<std::string>();
  }
  ii.import_info = fs::exists(in / "import.json") ? read_json_file(in / "import.json") : json();
  const std::string import_format = ii.import_info.is_object() ? ii.import_info.value("format", "") : "";
  ii.sam_scores = import_format == "sam-json" || import_format == "sam-png";
  // --tracks reads an id as one object along the capture; per-view ids (1 + list position) would chain
  // unrelated masks of neighbouring views wherever the points say nothing.
  if (opt.tracks && !import_format.empty() && import_format != "sam2-png")
    fail(
        "{}: --tracks: these masks were imported --from {}, whose ids are per view, not tracks (associate without "
        "--tracks)",
        (in / "import.json").string(), import_format);
  return ii;
}

// Every mask file must belong to a view (a stray mask means the masks and the model do not match).
void check_mask_stems(const Scene& s, const fs::path& in, const fs::path& model_dir) {
  std::map<std::string, int> by_stem;
  for (auto& v : s.views) by_stem[v.stem] = v.index;
  for (auto it = fs::recursive_directory_iterator(in); it != fs::recursive_directory_iterator(); ++it) {
    if (it->is_directory() &&
        (it->path().filename() == "per_view" || it->path().filename().string().starts_with("."))) {
      it.disable_recursion_pending();
      continue;
    }
    if (!it->is_regular_file() || it->path().extension() != ".png") continue;
    const std::string stem = fs::relative(it->path(), in).replace_extension().generic_string();
    if (!by_stem.count(stem))
      fail("{}: mask for an image that is not in the COLMAP model ({})", it->path().string(), model_dir.string());
  }
}

// ---- Phase 2: nodes and their 3D points ----

// The nodes of every view and what later phases read per view and per 3D point.
struct NodeSet {
  std::vector<Node> nodes;
  std::vector<std::map<int, int>> view_root;             // per view: per-view id -> root id
  std::vector<std::map<int, int>> view_node;             // per view: root id -> node
  std::vector<LabelMap> labels;                          // per view: root ids [H, W]; empty for a view without masks
  std::vector<std::vector<float>> reflattened_conf;      // [H, W] per view whose parts were clipped
  std::vector<std::vector<PointObservation>> point_obs;  // per 3D point; node: index into `nodes` or -1
  std::vector<long> core_count;                          // per node: keypoints in its core
  std::vector<std::vector<uint8_t>> cores;               // per view: core pixels (core_pixels) [H, W]
  std::vector<Eigen::Vector3d> point_xyz;                // [P] COLMAP's points, then the depth tracks' points
};

std::map<int, long> label_areas(const LabelMap& m) {
  std::map<int, long> area;
  for (uint16_t l : m.v)
    if (l) ++area[l];
  return area;
}

// import.json's record of view v's masks: id -> area, visibility, part_of.
std::map<int, MaskInfo> import_mask_info(const json& jv, const fs::path& in, const std::string& stem) {
  std::map<int, MaskInfo> info;
  if (jv.contains("masks") && jv["masks"].is_array())
    for (auto& e : jv["masks"]) {
      if (!e.is_object() || !e.contains("id"))
        fail("{}: view {}: mask entry without an id", (in / "import.json").string(), stem);
      MaskInfo mi;
      mi.area = e.value("area", 0.0);
      mi.visible = e.value("visible", 0.0);
      mi.part_of = e.contains("part_of") && e["part_of"].is_number() ? e["part_of"].get<int>() : 0;
      info[e["id"].get<int>()] = mi;
    }
  return info;
}

// --join-parts for view v: per-view id -> root id (a part -> its whole). With the parts clipped to their wholes
// (whole_pixels), m, area and the view's confidence are replaced by the clipped ones.
std::map<int, int> join_view_parts(const AssociateOptions& opt, const InputInfo& ii, const fs::path& in, const View& v,
                                   LabelMap& m, std::map<int, long>& area, std::vector<float>& reflattened_conf) {
  const json& import_info = ii.import_info;
  if (!(opt.join_parts && import_info.is_object() && import_info.contains("views") &&
        import_info["views"].contains(v.stem)))
    return {};
  std::map<int, MaskInfo> info = import_mask_info(import_info["views"][v.stem], in, v.stem);
  // SAM's own masks still there: part_of again at --part-fraction (import.json's is at 90%, which boundary
  // errors on small objects often miss). Ids are 1 + list position, as in import.json.
  const std::string fmt_name = import_info.value("format", "");
  const fs::path src_dir = import_info.value("source", "");
  const fs::path src = fmt_name == "sam-json" ? src_dir / (v.stem + ".json") : src_dir / v.stem;
  std::vector<SourceMask> sm;
  if ((opt.part_fraction < 0.9 || opt.whole_pixels) && (fmt_name == "sam-json" || fmt_name == "sam-png") &&
      fs::exists(src))
    sm = fmt_name == "sam-json" ? read_sam_json(src, v.width, v.height) : read_sam_png_folder(src, v.width, v.height);
  if (opt.part_fraction < 0.9 && !sm.empty()) {
    const std::vector<int> parent = part_of(sm, opt.part_fraction);
    for (size_t i = 0; i < sm.size(); ++i)
      if (auto it = info.find(int(i) + 1); it != info.end()) it->second.part_of = parent[i] >= 0 ? parent[i] + 1 : 0;
  }
  const std::map<int, int> root = part_roots(info, double(v.width) * v.height, opt.max_area);
  // The whole's outline: parts folded into it keep only their pixels inside it (whole_pixels, associate.h).
  if (opt.whole_pixels && !sm.empty()) {
    Flattened f;
    if (clip_parts_to_wholes(sm, root, v.width, v.height, f)) {
      m = std::move(f.labels);
      if (!f.confidence.empty()) reflattened_conf = std::move(f.confidence);
      area = label_areas(m);
    }
  }
  return root;
}

// One node per root of view v (a mask with its parts); m is relabelled to the root ids.
void add_view_nodes(const AssociateOptions& opt, const View& v, const std::map<int, long>& area,
                    const std::map<int, int>& root, LabelMap& m, NodeSet& ns, AssociateSummary& sum) {
  const double px = double(v.width) * v.height;
  std::map<int, int>& view_root = ns.view_root[v.index];
  for (auto& [l, a] : area) {
    auto it = root.find(l);
    view_root[l] = it == root.end() ? l : it->second;
  }
  std::map<int, long> root_area;
  for (auto& [l, a] : area) root_area[view_root[l]] += a;
  for (auto& [r, a] : root_area) {
    Node n;
    n.view = v.index, n.label = r, n.area = a;
    for (auto& [l, rr] : view_root)
      if (rr == r) {
        if (l == r) n.ids.insert(n.ids.begin(), l);
        else n.ids.push_back(l);
      }
    sum.joined_parts += int(n.ids.size()) - 1;
    if (a > opt.max_area * px)
      n.drop = fmt::format("background: covers {:.0f}% of the image (> --max-area {})", 100.0 * a / px, opt.max_area);
    ns.view_node[v.index][r] = int(ns.nodes.size());
    ns.nodes.push_back(std::move(n));
  }
  for (auto& l : m.v) l = l ? uint16_t(view_root[l]) : 0;
}

// 3D point `point` seen at pixel (x, y) of view `view`: an observation of the node there (if any).
void observe(NodeSet& ns, int point, int view, int x, int y) {
  const LabelMap& m = ns.labels[view];
  const int l = m.at(x, y);
  const int node = l ? ns.view_node[view][l] : -1;
  const bool is_core = ns.cores[view][size_t(y) * m.width + x];
  if (node >= 0) ns.nodes[node].points.push_back(point), ns.core_count[node] += is_core;
  ns.point_obs[point].push_back({view, node, is_core});
}

// Keypoints of view v -> the 3D points inside its masks (m: root ids, stored in ns with its core pixels).
void lift_keypoints(const AssociateOptions& opt, const Correspondences& cc, const View& v, LabelMap&& m, NodeSet& ns) {
  ns.cores[v.index] = core_pixels(m, opt.core_margin);
  ns.labels[v.index] = std::move(m);
  ns.core_count.resize(ns.nodes.size(), 0);
  auto imit = cc.image_index.find(v.colmap_id);
  if (imit == cc.image_index.end()) return;
  const ColmapImage& im = cc.model.images[size_t(imit->second)];
  for (size_t k = 0; k < im.point3d_ids.size(); ++k) {
    auto pit = cc.point_index.find(im.point3d_ids[k]);
    if (im.point3d_ids[k] < 0 || pit == cc.point_index.end()) continue;
    const int x = int(std::floor(im.xys[k].x())), y = int(std::floor(im.xys[k].y()));
    if (x < 0 || y < 0 || x >= v.width || y >= v.height) continue;
    observe(ns, pit->second, v.index, x, y);
  }
}

NodeSet read_nodes(const AssociateOptions& opt, const Scene& s, const fs::path& in, const InputInfo& ii,
                   const Correspondences& cc, AssociateSummary& sum) {
  const size_t V = s.views.size();
  NodeSet ns;
  ns.view_root.resize(V), ns.view_node.resize(V), ns.labels.resize(V);
  ns.reflattened_conf.resize(V), ns.cores.resize(V);
  ns.point_obs.resize(cc.model.points.size());
  for (auto& p : cc.model.points) ns.point_xyz.push_back(p.xyz);
  Progress bar("associate: read masks", long(V), opt.progress);
  for (auto& v : s.views) {
    const fs::path f = in / (v.stem + ".png");
    bar.update(v.index + 1, v.name);
    if (!fs::exists(f)) continue;
    LabelMap m = load_label_png(f);
    if (m.width != v.width || m.height != v.height)
      fail("{}: mask is {}x{} but its image {} is {}x{}", f.string(), m.width, m.height, v.name, v.width, v.height);
    ++sum.views_with_masks;
    std::map<int, long> area = label_areas(m);
    const std::map<int, int> root = join_view_parts(opt, ii, in, v, m, area, ns.reflattened_conf[v.index]);
    add_view_nodes(opt, v, area, root, m, ns, sum);
    lift_keypoints(opt, cc, v, std::move(m), ns);
  }
  bar.finish();
  return ns;
}

// Dense tracks from depth (depth_tracks.h), added after COLMAP's points.
void add_depth_tracks(const AssociateOptions& opt, const Scene& s, NodeSet& ns, AssociateSummary& sum) {
  std::vector<std::vector<float>> depth(s.views.size());
  std::vector<DepthCamera> cams(s.views.size());
  long pixels = 0;
  for (auto& v : s.views) {
    DepthCamera& c = cams[v.index];
    c.width = v.width, c.height = v.height, c.fx = v.fx, c.fy = v.fy, c.cx = v.cx, c.cy = v.cy, c.R = v.R, c.t = v.t;
    if (ns.labels[v.index].v.empty()) continue;  // a view without masks observes nothing, as for COLMAP's points
    depth[v.index] = opt.depth(v);
    if (depth[v.index].empty()) continue;
    if (depth[v.index].size() != size_t(v.width) * v.height)
      fail("depth of view {}: {} values for a {}x{} image", v.name, depth[v.index].size(), v.width, v.height);
    c.depth = depth[v.index].data();
    pixels += long(v.width) * v.height;
  }
  const int views_with_depth = int(std::count_if(cams.begin(), cams.end(), [](auto& c) { return c.depth != nullptr; }));
  const int stride =
      opt.depth_stride > 0
          ? opt.depth_stride
          : std::max(1, int(std::lround(std::sqrt(double(pixels) / std::max(1, views_with_depth) / 4096.0))));
  DepthTracks dt = depth_tracks(cams, stride, opt.depth_tolerance);
  sum.depth_points = long(dt.xyz.size());
  ns.point_obs.resize(ns.point_xyz.size() + dt.xyz.size());
  for (size_t t = 0; t < dt.xyz.size(); ++t) {
    const int idx = int(ns.point_xyz.size());
    ns.point_xyz.push_back(dt.xyz[t]);
    for (const DepthObservation& o : dt.obs[t]) observe(ns, idx, o.view, o.x, o.y);
  }
}

// ---- Phase 3: clustering, votes, attaching ----

// The objects found: each node's object and each 3D point's.
struct Objects {
  int count = 0;
  std::vector<int> object_of;     // node -> object index, or -1
  std::vector<int> point_object;  // 3D point -> object index by vote, or -1
};

// Drops the nodes with too few 3D points (the background ones are dropped already); returns the kept nodes.
std::vector<int> keep_liftable(const AssociateOptions& opt, std::vector<Node>& nodes, AssociateSummary& sum) {
  std::vector<int> node_of_kept;
  for (size_t i = 0; i < nodes.size(); ++i) {
    Node& n = nodes[i];
    // With tracks, a mask with few points rides its track (cluster.h) instead of being dropped.
    if (n.drop.empty() && !opt.tracks && long(n.points.size()) < opt.min_points)
      n.drop = fmt::format("unliftable: {} 3D points inside (< --min-points {})", n.points.size(), opt.min_points);
    if (!n.drop.empty()) {
      (n.drop.starts_with("background") ? sum.dropped_background : sum.dropped_few_points)++;
      continue;
    }
    node_of_kept.push_back(int(i));
  }
  return node_of_kept;
}

// The graph over the kept nodes (cluster.h).
MaskGraph kept_graph(const AssociateOptions& opt, int num_views, NodeSet& ns, const std::vector<int>& node_of_kept) {
  std::vector<int> kept_of(ns.nodes.size(), -1), kept_view;
  for (size_t k = 0; k < node_of_kept.size(); ++k) {
    kept_of[node_of_kept[k]] = int(k);
    kept_view.push_back(ns.nodes[node_of_kept[k]].view);
  }
  // A mask too small to have min_points core points lifts all its points.
  ns.core_count.resize(ns.nodes.size(), 0);
  std::vector<std::vector<PointObservation>> point_obs(ns.point_obs.size());
  for (size_t p = 0; p < ns.point_obs.size(); ++p)
    for (auto& o : ns.point_obs[p])
      point_obs[p].push_back(
          {o.view, o.node >= 0 ? kept_of[o.node] : -1, o.node < 0 || o.core || ns.core_count[o.node] < opt.min_points});
  MaskGraph g = build_mask_graph(num_views, kept_view, point_obs);
  g.whole.assign(node_of_kept.size(), 0);
  for (size_t k = 0; k < node_of_kept.size(); ++k) g.whole[k] = ns.nodes[node_of_kept[k]].ids.size() > 1;
  if (opt.tracks)
    for (size_t k = 0; k < node_of_kept.size(); ++k) g.track.push_back(ns.nodes[node_of_kept[k]].label);
  return g;
}

// Clusters the kept nodes into objects; a kept node in no object gets the reason in its `drop`.
Objects cluster_nodes(const AssociateOptions& opt, int num_views, NodeSet& ns, AssociateSummary& sum) {
  const std::vector<int> node_of_kept = keep_liftable(opt, ns.nodes, sum);
  const MaskGraph g = kept_graph(opt, num_views, ns, node_of_kept);
  ClusterOptions co;
  co.min_affinity = opt.min_affinity;
  co.min_views = opt.min_views;
  co.min_points = opt.min_points;
  co.track_split = opt.track_split;
  co.part_merge = opt.join_parts ? opt.part_merge : 0;
  const Clustering c = cluster_masks(g, co);
  Objects obj;
  obj.count = c.num_objects;
  obj.object_of.assign(ns.nodes.size(), -1);
  std::vector<int> alone;  // kept nodes in no object
  for (size_t k = 0; k < node_of_kept.size(); ++k) {
    obj.object_of[node_of_kept[k]] = c.cluster[k];
    if (c.cluster[k] < 0) alone.push_back(int(k));
  }
  // Why each of those joined no object: its best affinity, and whether that object has a mask in its view.
  const std::vector<NodeMatch> near = nearest_objects(g, c, alone, co);
  for (size_t i = 0; i < alone.size(); ++i) {
    const NodeMatch& m = near[i];
    const std::string why = m.object < 0
                                ? "no 3D point shared with any object"
                                : fmt::format("closest object #{} at affinity {:.2f}{}", m.object + 1, m.affinity,
                                              m.same_view ? " already has a mask in this view" : " (< --min-affinity)");
    ns.nodes[node_of_kept[alone[i]]].drop =
        fmt::format("seen in fewer than --min-views {} views; {}", opt.min_views, why);
    ++sum.dropped_few_views;
  }
  return obj;
}

// Point votes: a 3D point belongs to the object that most of its observations' masks belong to (ties: smaller).
void vote_points(const NodeSet& ns, Objects& obj) {
  const std::vector<int>& object_of = obj.object_of;
  obj.point_object.assign(ns.point_obs.size(), -1);
  std::vector<int> votes(obj.count, 0), touched;
  for (size_t p = 0; p < ns.point_obs.size(); ++p) {
    touched.clear();
    for (auto& o : ns.point_obs[p])
      if (o.node >= 0 && object_of[o.node] >= 0 && !votes[object_of[o.node]]++) touched.push_back(object_of[o.node]);
    int best = -1;
    for (int k : touched)
      if (best < 0 || votes[k] > votes[best] || (votes[k] == votes[best] && k < best)) best = k;
    for (int k : touched) votes[k] = 0;
    obj.point_object[p] = best;
  }
}

// Attach: a mask left out (too few 3D points to cluster, or alone) joins the object that holds at least half of
// its 3D points, when that object has no mask in its view yet; best share first.
void attach_left_out(std::vector<Node>& nodes, Objects& obj, AssociateSummary& sum) {
  std::set<std::pair<int, int>> taken;  // (view, object)
  for (size_t i = 0; i < nodes.size(); ++i)
    if (obj.object_of[i] >= 0) taken.insert({nodes[i].view, obj.object_of[i]});
  struct Cand {
    double share;
    long points;
    int node, object;
  };
  std::vector<Cand> cands;
  for (size_t i = 0; i < nodes.size(); ++i) {
    const Node& n = nodes[i];
    if (obj.object_of[i] >= 0 || n.points.empty() || n.drop.starts_with("background")) continue;
    std::map<int, long> votes;
    for (int p : n.points)
      if (obj.point_object[p] >= 0) ++votes[obj.point_object[p]];
    int best = -1;
    for (auto& [k, cnt] : votes)
      if (best < 0 || cnt > votes[best]) best = k;
    if (best < 0 || 2 * votes[best] < long(n.points.size())) continue;
    cands.push_back({double(votes[best]) / double(n.points.size()), long(n.points.size()), int(i), best});
  }
  std::sort(cands.begin(), cands.end(), [](const Cand& a, const Cand& b) {
    if (a.share != b.share) return a.share > b.share;
    if (a.points != b.points) return a.points > b.points;
    return a.node < b.node;
  });
  for (const Cand& cd : cands) {
    Node& n = nodes[cd.node];
    if (!taken.insert({n.view, cd.object}).second) continue;
    (n.drop.starts_with("unliftable") ? sum.dropped_few_points : sum.dropped_few_views)--;
    n.drop.clear();
    obj.object_of[cd.node] = cd.object;
    ++sum.attached;
  }
}

// ---- Phase 4: objects' spread, ids and names ----

// 3D spread of each object's voted points relative to all points (robust: a few stray points do not count), over
// COLMAP's points only (--surface-spread is calibrated on them; lifted depth pixels sample the views' visible
// surfaces evenly, which weighs large backgrounds differently). obj_points: every voted point, depth ones too.
std::vector<double> object_spread(const NodeSet& ns, const Objects& obj, size_t colmap_points,
                                  std::vector<long>& obj_points) {
  const int K = obj.count;
  std::vector<double> spread(K, 0);
  obj_points.assign(K, 0);
  std::vector<std::vector<Eigen::Vector3d>> pts(K);
  std::vector<Eigen::Vector3d> all;
  for (size_t p = 0; p < obj.point_object.size(); ++p) {
    const int k = obj.point_object[p];
    if (k >= 0) ++obj_points[k];
    if (p >= colmap_points) continue;
    all.push_back(ns.point_xyz[p]);
    if (k >= 0) pts[k].push_back(ns.point_xyz[p]);
  }
  const double all_spread = robust_spread(all);
  for (int k = 0; k < K; ++k)
    if (all_spread > 0 && !pts[k].empty()) spread[k] = robust_spread(pts[k]) / all_spread;
  return spread;
}

// The names given to an object's masks: per node, the first of its ids with a name (--names, then objects.json).
std::vector<std::string> member_names(const std::vector<int>& members, const std::vector<Node>& nodes, const Scene& s,
                                      const InputInfo& ii) {
  const json& names_file = ii.names_file;
  std::vector<std::string> names;
  for (int ni : members) {
    const Node& n = nodes[ni];
    const std::string& stem = s.views[n.view].stem;
    for (int id : n.ids) {
      const std::string key = std::to_string(id);
      if (names_file.is_object() && names_file.contains(stem) && names_file[stem].is_object() &&
          names_file[stem].contains(key) && names_file[stem][key].is_string()) {
        names.push_back(names_file[stem][key].get<std::string>());
        break;
      }
      if (auto it = ii.global_names.find(id); it != ii.global_names.end()) {
        names.push_back(it->second);
        break;
      }
    }
  }
  return names;
}

// Objects: ids 1.. in cluster order (dropped surfaces removed), names by majority over their masks. Fills
// sum.objects; returns object index -> final id (0 = dropped).
std::vector<int> number_objects(const AssociateOptions& opt, const Scene& s, const InputInfo& ii, const Objects& obj,
                                NodeSet& ns, AssociateSummary& sum) {
  const int K = obj.count;
  std::vector<Node>& nodes = ns.nodes;
  std::vector<std::vector<int>> members(K);  // node indices of each object
  for (size_t i = 0; i < nodes.size(); ++i)
    if (obj.object_of[i] >= 0) members[obj.object_of[i]].push_back(int(i));
  std::vector<long> obj_points;
  const std::vector<double> spread = object_spread(ns, obj, size_t(sum.colmap_points), obj_points);
  std::vector<int> final_id(K, 0);
  for (int k = 0, next = 1; k < K; ++k) {
    const bool surface = spread[k] > opt.surface_spread;
    if (surface && opt.drop_surfaces) {
      for (int ni : members[k])
        nodes[ni].drop = fmt::format("surface: 3D spread {:.2f} of the scene's (> --surface-spread {})", spread[k],
                                     opt.surface_spread);
      ++sum.dropped_surface;
      continue;
    }
    AssociatedObject o;
    o.id = final_id[k] = next++;
    o.masks = int(members[k].size());
    std::vector<char> seen(s.views.size(), 0);
    for (int ni : members[k]) {
      o.views += !seen[nodes[ni].view];
      seen[nodes[ni].view] = 1;
    }
    const std::vector<std::string> names = member_names(members[k], nodes, s, ii);
    o.name = names.empty() ? fmt::format("object {}", o.id) : most_common(names);
    o.points = obj_points[k];
    o.spread = spread[k];
    o.surface = surface;
    sum.objects.push_back(o);
  }
  return final_id;
}

// ---- Phase 5: the output folder ----

// The confidence written beside view v's associated mask `out` (empty: none, or the input's copied as it is).
// The ramp replaces what a per-pixel confidence would say: only for SAM's per-mask scores (flat up to the edge)
// and masks without any confidence; a per-pixel confidence (SAM2's, the user's) is kept as it is.
void write_confidence(const AssociateOptions& opt, const InputInfo& ii, const fs::path& in, const fs::path& tmp,
                      const View& v, const LabelMap& out, std::vector<float> conf) {
  const fs::path conf_file = in / (v.stem + ".conf.npy");
  const bool flat = ii.sam_scores || !fs::exists(conf_file);
  if (conf.empty() && flat && opt.edge_ramp > 0 && fs::exists(conf_file)) {
    conf = read_npy(conf_file).to_float();
    if (conf.size() != size_t(v.width) * v.height)
      fail("{}: {} confidences for a {}x{} view", conf_file.string(), conf.size(), v.width, v.height);
  }
  if (flat && opt.edge_ramp > 0) edge_ramp_confidence(out, opt.edge_ramp, conf);
  if (!conf.empty())
    write_npy(tmp / (v.stem + ".conf.npy"), make_npy_f32({size_t(v.height), size_t(v.width)}, conf.data()));
  else if (fs::exists(conf_file)) fs::copy_file(conf_file, tmp / (v.stem + ".conf.npy"));
}

// Writes view v's mask with the final ids (and its confidence) into tmp; returns its per-view id -> final id
// record and appends its dropped masks to `dropped`.
json write_view(const AssociateOptions& opt, const InputInfo& ii, const fs::path& in, const fs::path& tmp,
                const View& v, const Objects& obj, const std::vector<int>& final_id, NodeSet& ns, json& dropped) {
  std::map<int, int> new_id;  // root id -> final id (0 = dropped)
  json jv = json::object();
  for (auto& [r, ni] : ns.view_node[v.index]) {
    const Node& n = ns.nodes[ni];
    const int k = obj.object_of[ni];
    new_id[r] = k >= 0 ? final_id[k] : 0;
    if (new_id[r] == 0)
      dropped.push_back({{"view", v.stem},
                         {"id", r},
                         {"ids", n.ids},
                         {"pixels", n.area},
                         {"points", n.points.size()},
                         {"reason", n.drop}});
  }
  for (auto& [l, r] : ns.view_root[v.index]) jv[std::to_string(l)] = new_id[r] ? json(new_id[r]) : json(nullptr);
  LabelMap out = ns.labels[v.index];
  for (auto& l : out.v) l = l ? uint16_t(new_id[l]) : 0;
  const fs::path png = tmp / (v.stem + ".png");
  ensure_dir(png.parent_path());
  save_label_png(png, out);
  write_confidence(opt, ii, in, tmp, v, out, std::move(ns.reflattened_conf[v.index]));
  return jv;
}

// associate.json: the options, the counts, the objects, the dropped masks and every view's id table.
json report_json(const AssociateOptions& opt, const Folders& f, const fs::path& images_file,
                 const AssociateSummary& sum, const json& list, const json& dropped, const json& views) {
  // Where the per-view input is after this run (in place: masks/per_view, whatever it was read from).
  return {{"source", fs::absolute(f.in_place ? f.masks_dir / "per_view" : f.in).lexically_normal().string()},
          {"colmap", images_file.string()},
          {"options",
           {{"min_affinity", opt.min_affinity},
            {"min_views", opt.min_views},
            {"min_points", opt.min_points},
            {"max_area", opt.max_area},
            {"core_margin", opt.core_margin},
            {"attach", opt.attach},
            {"join_parts", opt.join_parts},
            {"part_fraction", opt.part_fraction},
            {"part_merge", opt.part_merge},
            {"whole_pixels", opt.whole_pixels},
            {"tracks", opt.tracks},
            {"track_split", opt.track_split},
            {"edge_ramp", opt.edge_ramp},
            {"drop_surfaces", opt.drop_surfaces},
            {"surface_spread", opt.surface_spread},
            {"depth", bool(opt.depth)},
            {"depth_stride", opt.depth_stride},
            {"depth_tolerance", opt.depth_tolerance}}},
          {"colmap_points", sum.colmap_points},
          {"depth_points", sum.depth_points},
          {"views_with_masks", sum.views_with_masks},
          {"masks", sum.masks},
          {"joined_parts", sum.joined_parts},
          {"attached", sum.attached},
          {"objects", list},
          {"dropped", dropped},
          {"ids", views}};
}

// The per-view input, as it was, in tmp/per_view/ (the in-place run's backup).
void keep_input(const Folders& f, const fs::path& tmp) {
  const fs::path keep = tmp / "per_view";
  if (f.associated) {
    fs::copy(f.in, keep, fs::copy_options::recursive);
    return;
  }
  ensure_dir(keep);
  for (auto& e : fs::directory_iterator(f.in)) {
    if (e.path().filename().string().starts_with(".")) continue;
    fs::copy(e.path(), keep / e.path().filename(), fs::copy_options::recursive);
  }
}

// Replaces dst by tmp (the old dst moved aside first, removed last).
void swap_in(const fs::path& tmp, const fs::path& dst, const std::string& suffix) {
  const fs::path old = dst.parent_path() / fmt::format(".{}.old-{}", dst.filename().string(), suffix);
  std::error_code ec;
  if (fs::exists(dst)) {
    fs::rename(dst, old, ec);
    if (ec) fail("{}: cannot move the old folder aside ({})", dst.string(), ec.message());
  }
  fs::rename(tmp, dst, ec);
  if (ec) fail("{}: cannot move the associated masks into place ({})", dst.string(), ec.message());
  fs::remove_all(old, ec);
}

// Writes the masks, objects.json, associate.json (and in place, per_view/) into a temporary folder beside the
// destination and swaps it in; a failure removes the temporary folder.
void write_output(const AssociateOptions& opt, const Scene& s, const Folders& f, const Correspondences& cc,
                  const InputInfo& ii, const Objects& obj, const std::vector<int>& final_id, NodeSet& ns,
                  AssociateSummary& sum) {
  const std::string suffix = fmt::format("{:08x}", std::random_device{}());
  const fs::path dst = f.in_place ? f.masks_dir : fs::absolute(opt.out_masks).lexically_normal();
  ensure_dir(dst.parent_path());
  const fs::path tmp = dst.parent_path() / fmt::format(".{}.associate-{}", dst.filename().string(), suffix);
  try {
    ensure_dir(tmp);
    json views = json::object(), dropped = json::array();
    Progress bar("associate: write masks", long(s.views.size()), opt.progress);
    for (auto& v : s.views) {
      bar.update(v.index + 1, v.name);
      if (ns.labels[v.index].v.empty()) continue;
      views[v.stem] = write_view(opt, ii, f.in, tmp, v, obj, final_id, ns, dropped);
    }
    bar.finish();
    json objects = json::object(), list = json::array();
    for (auto& o : sum.objects) {
      objects[std::to_string(o.id)] = o.name;
      list.push_back({{"id", o.id},
                      {"name", o.name},
                      {"views", o.views},
                      {"masks", o.masks},
                      {"points", o.points},
                      {"spread", std::round(o.spread * 1000) / 1000},
                      {"surface", o.surface}});
    }
    atomic_write_text(tmp / "objects.json", objects.dump(2) + "\n");
    const json report = report_json(opt, f, cc.images_file, sum, list, dropped, views);
    atomic_write_text(tmp / "associate.json", report.dump(1) + "\n");
    if (f.in_place) {
      keep_input(f, tmp);
      sum.backup_dir = f.masks_dir / "per_view";
    }
    swap_in(tmp, dst, suffix);
  } catch (const fs::filesystem_error& e) {
    std::error_code ec;
    fs::remove_all(tmp, ec);
    fail("{}: {}", dst.string(), e.what());
  } catch (...) {
    std::error_code ec;
    fs::remove_all(tmp, ec);
    throw;
  }
  sum.out_dir = dst;
}

}  // namespace

AssociateSummary associate_masks(const AssociateOptions& opt) {
  check_options(opt);
  const Scene s = load_scene(opt.scene);
  const Folders f = find_folders(opt, s);
  const Correspondences cc = read_correspondences(s);
  const InputInfo ii = read_input_info(opt, f.in);
  check_mask_stems(s, f.in, cc.model_dir);

  AssociateSummary sum;
  sum.views = int(s.views.size());
  NodeSet ns = read_nodes(opt, s, f.in, ii, cc, sum);
  sum.colmap_points = long(cc.model.points.size());
  if (opt.depth) add_depth_tracks(opt, s, ns, sum);
  if (sum.views_with_masks == 0) fail("{}: no <stem>.png mask for any view of the scene", f.in.string());
  sum.masks = int(ns.nodes.size());

  Objects obj = cluster_nodes(opt, int(s.views.size()), ns, sum);
  vote_points(ns, obj);
  if (opt.attach) {
    attach_left_out(ns.nodes, obj, sum);
    vote_points(ns, obj);
  }
  const std::vector<int> final_id = number_objects(opt, s, ii, obj, ns, sum);
  write_output(opt, s, f, cc, ii, obj, final_id, ns, sum);
  return sum;
}

}  // namespace hgs::masks
