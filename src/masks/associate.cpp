// Association driver (steps in associate.h): read the per-view masks and COLMAP's keypoint -> 3D point table,
// make (view, mask) nodes, cluster them (cluster.h), name and number the objects, write the consistent label maps
// and the report into a temporary folder and swap it in.
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

json read_json(const fs::path& p) {
  try {
    return json::parse(read_file_text(p));
  } catch (const json::exception& e) {
    fail("{}: invalid JSON ({})", p.string(), e.what());
  }
}

bool non_empty_dir(const fs::path& d) { return fs::is_directory(d) && !fs::is_empty(d); }

struct Node {
  int view = 0;
  int label = 0;     // root id in the per-view map
  long area = 0;     // pixels
  std::vector<int> points;  // dense point indices inside the mask
  std::string drop;  // reason when dropped before clustering
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

}  // namespace

AssociateSummary associate_masks(const AssociateOptions& opt) {
  if (opt.min_views < 1) fail("--min-views: must be at least 1, got {}", opt.min_views);
  if (opt.min_points < 1) fail("--min-points: must be at least 1, got {}", opt.min_points);
  if (!(opt.max_area > 0 && opt.max_area <= 1)) fail("--max-area: must be in (0, 1], got {}", opt.max_area);
  if (!(opt.min_affinity > 0 && opt.min_affinity <= 1)) fail("--min-affinity: must be in (0, 1], got {}", opt.min_affinity);
  Scene s = load_scene(opt.scene);
  const fs::path masks_dir = s.root / "masks";
  const bool associated = fs::exists(masks_dir / "associate.json");
  const bool in_place = opt.out_masks.empty();
  if (associated && in_place && !opt.force)
    fail("{}: masks are already associated (associate.json); pass --force to associate again from masks/per_view",
         masks_dir.string());
  const fs::path in = associated ? masks_dir / "per_view" : masks_dir;
  if (!fs::is_directory(in)) fail("{}: no masks folder (per-view masks/<stem>.png, e.g. from `hgs masks import`)", in.string());
  if (associated && !fs::is_directory(in)) fail("{}: associate.json but no per_view/ folder with the original masks", masks_dir.string());
  if (!in_place && !opt.force && non_empty_dir(opt.out_masks))
    fail("{}: already exists and is not empty; pass --force to replace it", opt.out_masks.string());

  // COLMAP 2D-3D correspondences.
  const fs::path model_dir = fs::is_directory(s.root / "sparse" / "0") ? s.root / "sparse" / "0" : s.root / "sparse";
  ColmapModel model = read_colmap(model_dir);
  const fs::path images_file = model_dir / (fs::exists(model_dir / "images.bin") ? "images.bin" : "images.txt");
  std::unordered_map<int64_t, int> point_index;
  for (size_t i = 0; i < model.points.size(); ++i) point_index[int64_t(model.points[i].id)] = int(i);
  std::map<int, const ColmapImage*> image_by_id;
  size_t observed = 0;
  for (auto& im : model.images) {
    image_by_id[im.id] = &im;
    for (int64_t p : im.point3d_ids) observed += p >= 0 && point_index.count(p);
  }
  if (observed == 0)
    fail("{}: no keypoint observes a 3D point (the model has no 2D-3D correspondences; run COLMAP's mapper or point_triangulator)",
         images_file.string());

  // Names: --names file (per view) or objects.json of the input (the same id in every view).
  json names_file = opt.names.empty() ? json() : read_json(opt.names);
  if (!opt.names.empty() && !names_file.is_object()) fail("{}: expected {{\"<stem>\": {{\"<id>\": \"name\"}}}}", opt.names.string());
  std::map<int, std::string> global_names;
  if (fs::exists(in / "objects.json")) {
    json j = read_json(in / "objects.json");
    if (!j.is_object()) fail("{}: expected {{\"<id>\": \"name\"}}", (in / "objects.json").string());
    for (auto& [k, v] : j.items())
      if (v.is_string()) global_names[std::atoi(k.c_str())] = v.get<std::string>();
  }
  json import_info = fs::exists(in / "import.json") ? read_json(in / "import.json") : json();
  const std::string import_format = import_info.is_object() ? import_info.value("format", "") : "";
  const bool sam_scores = import_format == "sam-json" || import_format == "sam-png";  // one score per mask

  // Every mask file must belong to a view (a stray mask means the masks and the model do not match).
  {
    std::map<std::string, int> by_stem;
    for (auto& v : s.views) by_stem[v.stem] = v.index;
    for (auto it = fs::recursive_directory_iterator(in); it != fs::recursive_directory_iterator(); ++it) {
      if (it->is_directory() && (it->path().filename() == "per_view" || it->path().filename().string().starts_with("."))) {
        it.disable_recursion_pending();
        continue;
      }
      if (!it->is_regular_file() || it->path().extension() != ".png") continue;
      const std::string stem = fs::relative(it->path(), in).replace_extension().generic_string();
      if (!by_stem.count(stem)) fail("{}: mask for an image that is not in the COLMAP model ({})", it->path().string(), model_dir.string());
    }
  }

  // Nodes.
  AssociateSummary sum;
  sum.views = int(s.views.size());
  std::vector<Node> nodes;
  std::vector<std::map<int, int>> view_root(s.views.size());  // per view: per-view id -> root id
  std::vector<std::map<int, int>> view_node(s.views.size());  // per view: root id -> node
  std::vector<LabelMap> labels(s.views.size());
  std::vector<std::vector<float>> reflattened_conf(s.views.size());  // [H, W] per view whose parts were clipped
  std::vector<std::vector<PointObservation>> point_obs_raw(model.points.size());  // node: index into `nodes` or -1
  std::vector<long> core_count;  // per node: keypoints in its core
  std::vector<std::vector<uint8_t>> cores(s.views.size());  // per view: core pixels (core_pixels)
  std::vector<Eigen::Vector3d> point_xyz;  // [P] COLMAP's points, then the depth tracks' points
  for (auto& p : model.points) point_xyz.push_back(p.xyz);
  {
    Progress bar("associate: read masks", long(s.views.size()), opt.progress);
    for (auto& v : s.views) {
      const fs::path f = in / (v.stem + ".png");
      bar.update(v.index + 1, v.name);
      if (!fs::exists(f)) continue;
      LabelMap m = load_label_png(f);
      if (m.width != v.width || m.height != v.height)
        fail("{}: mask is {}x{} but its image {} is {}x{}", f.string(), m.width, m.height, v.name, v.width, v.height);
      ++sum.views_with_masks;
      const double px = double(v.width) * v.height;
      std::map<int, long> area;
      for (uint16_t l : m.v)
        if (l) ++area[l];
      std::map<int, int> root;
      if (opt.join_parts && import_info.is_object() && import_info.contains("views") && import_info["views"].contains(v.stem)) {
        const json& jv = import_info["views"][v.stem];
        std::map<int, MaskInfo> info;
        if (jv.contains("masks") && jv["masks"].is_array())
          for (auto& e : jv["masks"]) {
            if (!e.is_object() || !e.contains("id")) fail("{}: view {}: mask entry without an id", (in / "import.json").string(), v.stem);
            MaskInfo mi;
            mi.area = e.value("area", 0.0);
            mi.visible = e.value("visible", 0.0);
            mi.part_of = e.contains("part_of") && e["part_of"].is_number() ? e["part_of"].get<int>() : 0;
            info[e["id"].get<int>()] = mi;
          }
        // SAM's own masks still there: part_of again at --part-fraction (import.json's is at 90%, which boundary
        // errors on small objects often miss). Ids are 1 + list position, as in import.json.
        const std::string fmt_name = import_info.value("format", "");
        const fs::path src_dir = import_info.value("source", "");
        const fs::path src = fmt_name == "sam-json" ? src_dir / (v.stem + ".json") : src_dir / v.stem;
        std::vector<SourceMask> sm;
        if ((opt.part_fraction < 0.9 || opt.whole_pixels) && (fmt_name == "sam-json" || fmt_name == "sam-png") && fs::exists(src))
          sm = fmt_name == "sam-json" ? read_sam_json(src, v.width, v.height) : read_sam_png_folder(src, v.width, v.height);
        if (opt.part_fraction < 0.9 && !sm.empty()) {
          const std::vector<int> parent = part_of(sm, opt.part_fraction);
          for (size_t i = 0; i < sm.size(); ++i)
            if (auto it = info.find(int(i) + 1); it != info.end()) it->second.part_of = parent[i] >= 0 ? parent[i] + 1 : 0;
        }
        root = part_roots(info, px, opt.max_area);
        // The whole's outline: parts folded into it keep only their pixels inside it (whole_pixels, associate.h).
        if (opt.whole_pixels && !sm.empty()) {
          Flattened f;
          if (clip_parts_to_wholes(sm, root, v.width, v.height, f)) {
            m = std::move(f.labels);
            if (!f.confidence.empty()) reflattened_conf[v.index] = std::move(f.confidence);
            area.clear();
            for (uint16_t l : m.v)
              if (l) ++area[l];
          }
        }
      }
      for (auto& [l, a] : area) {
        auto it = root.find(l);
        view_root[v.index][l] = it == root.end() ? l : it->second;
      }
      std::map<int, long> root_area;
      for (auto& [l, a] : area) root_area[view_root[v.index][l]] += a;
      for (auto& [r, a] : root_area) {
        Node n;
        n.view = v.index, n.label = r, n.area = a;
        for (auto& [l, rr] : view_root[v.index])
          if (rr == r) {
            if (l == r) n.ids.insert(n.ids.begin(), l);
            else n.ids.push_back(l);
          }
        sum.joined_parts += int(n.ids.size()) - 1;
        if (a > opt.max_area * px) n.drop = fmt::format("background: covers {:.0f}% of the image (> --max-area {})", 100.0 * a / px, opt.max_area);
        view_node[v.index][r] = int(nodes.size());
        nodes.push_back(std::move(n));
      }
      for (auto& l : m.v) l = l ? uint16_t(view_root[v.index][l]) : 0;
      // Keypoints -> 3D points.
      const std::vector<uint8_t> core = core_pixels(m, opt.core_margin);
      core_count.resize(nodes.size(), 0);
      auto imit = image_by_id.find(v.colmap_id);
      if (imit != image_by_id.end()) {
        const ColmapImage& im = *imit->second;
        for (size_t k = 0; k < im.point3d_ids.size(); ++k) {
          auto pit = point_index.find(im.point3d_ids[k]);
          if (im.point3d_ids[k] < 0 || pit == point_index.end()) continue;
          const int x = int(std::floor(im.xys[k].x())), y = int(std::floor(im.xys[k].y()));
          if (x < 0 || y < 0 || x >= v.width || y >= v.height) continue;
          const int l = m.at(x, y);
          const int node = l ? view_node[v.index][l] : -1;
          const bool is_core = core[size_t(y) * v.width + x];
          if (node >= 0) nodes[node].points.push_back(pit->second), core_count[node] += is_core;
          point_obs_raw[pit->second].push_back({v.index, node, is_core});
        }
      }
      labels[v.index] = std::move(m);
      cores[v.index] = core;
    }
    bar.finish();
  }
  sum.colmap_points = long(model.points.size());
  if (opt.depth) {
    // Dense tracks from depth (depth_tracks.h), added after COLMAP's points.
    std::vector<std::vector<float>> depth(s.views.size());
    std::vector<DepthCamera> cams(s.views.size());
    long pixels = 0;
    for (auto& v : s.views) {
      DepthCamera& c = cams[v.index];
      c.width = v.width, c.height = v.height, c.fx = v.fx, c.fy = v.fy, c.cx = v.cx, c.cy = v.cy, c.R = v.R, c.t = v.t;
      if (labels[v.index].v.empty()) continue;  // a view without masks observes nothing, as for COLMAP's points
      depth[v.index] = opt.depth(v);
      if (depth[v.index].empty()) continue;
      if (depth[v.index].size() != size_t(v.width) * v.height)
        fail("depth of view {}: {} values for a {}x{} image", v.name, depth[v.index].size(), v.width, v.height);
      c.depth = depth[v.index].data();
      pixels += long(v.width) * v.height;
    }
    const int views_with_depth = int(std::count_if(cams.begin(), cams.end(), [](auto& c) { return c.depth != nullptr; }));
    const int stride = opt.depth_stride > 0 ? opt.depth_stride
                                            : std::max(1, int(std::lround(std::sqrt(double(pixels) / std::max(1, views_with_depth) / 4096.0))));
    DepthTracks dt = depth_tracks(cams, stride, opt.depth_tolerance);
    sum.depth_points = long(dt.xyz.size());
    point_obs_raw.resize(model.points.size() + dt.xyz.size());
    for (size_t t = 0; t < dt.xyz.size(); ++t) {
      const int idx = int(point_xyz.size());
      point_xyz.push_back(dt.xyz[t]);
      for (const DepthObservation& o : dt.obs[t]) {
        const LabelMap& m = labels[o.view];
        const int l = m.at(o.x, o.y);
        const int node = l ? view_node[o.view][l] : -1;
        const bool is_core = cores[o.view][size_t(o.y) * m.width + o.x];
        if (node >= 0) nodes[node].points.push_back(idx), core_count[node] += is_core;
        point_obs_raw[idx].push_back({o.view, node, is_core});
      }
    }
  }
  if (sum.views_with_masks == 0) fail("{}: no <stem>.png mask for any view of the scene", in.string());
  sum.masks = int(nodes.size());

  // Graph over the kept nodes.
  std::vector<int> kept_of(nodes.size(), -1), node_of_kept, kept_view;
  for (size_t i = 0; i < nodes.size(); ++i) {
    Node& n = nodes[i];
    if (n.drop.empty() && long(n.points.size()) < opt.min_points)
      n.drop = fmt::format("unliftable: {} 3D points inside (< --min-points {})", n.points.size(), opt.min_points);
    if (!n.drop.empty()) {
      (n.drop.starts_with("background") ? sum.dropped_background : sum.dropped_few_points)++;
      continue;
    }
    kept_of[i] = int(node_of_kept.size());
    node_of_kept.push_back(int(i));
    kept_view.push_back(n.view);
  }
  // A mask too small to have min_points core points lifts all its points.
  core_count.resize(nodes.size(), 0);
  std::vector<std::vector<PointObservation>> point_obs(point_obs_raw.size());
  for (size_t p = 0; p < point_obs_raw.size(); ++p)
    for (auto& o : point_obs_raw[p])
      point_obs[p].push_back({o.view, o.node >= 0 ? kept_of[o.node] : -1, o.node < 0 || o.core || core_count[o.node] < opt.min_points});
  MaskGraph g = build_mask_graph(int(s.views.size()), kept_view, point_obs);
  g.whole.assign(node_of_kept.size(), 0);
  for (size_t k = 0; k < node_of_kept.size(); ++k) g.whole[k] = nodes[node_of_kept[k]].ids.size() > 1;
  ClusterOptions co;
  co.min_affinity = opt.min_affinity;
  co.min_views = opt.min_views;
  co.min_points = opt.min_points;
  co.part_merge = opt.join_parts ? opt.part_merge : 0;
  Clustering c = cluster_masks(g, co);
  std::vector<int> object_of(nodes.size(), -1);  // node -> object index
  std::vector<int> alone;  // kept nodes in no object
  for (size_t k = 0; k < node_of_kept.size(); ++k) {
    object_of[node_of_kept[k]] = c.cluster[k];
    if (c.cluster[k] < 0) alone.push_back(int(k));
  }
  // Why each of those joined no object: its best affinity, and whether that object has a mask in its view.
  const std::vector<NodeMatch> near = nearest_objects(g, c, alone, co);
  for (size_t i = 0; i < alone.size(); ++i) {
    const NodeMatch& m = near[i];
    const std::string why = m.object < 0 ? "no 3D point shared with any object"
                                         : fmt::format("closest object #{} at affinity {:.2f}{}", m.object + 1, m.affinity,
                                                       m.same_view ? " already has a mask in this view" : " (< --min-affinity)");
    nodes[node_of_kept[alone[i]]].drop = fmt::format("seen in fewer than --min-views {} views; {}", opt.min_views, why);
    ++sum.dropped_few_views;
  }

  // Point votes: a 3D point belongs to the object that most of its observations' masks belong to (ties: smaller).
  const int K = c.num_objects;
  std::vector<int> point_object(point_obs_raw.size(), -1);
  auto vote_points = [&] {
    std::vector<int> votes(K, 0), touched;
    for (size_t p = 0; p < point_obs_raw.size(); ++p) {
      touched.clear();
      for (auto& o : point_obs_raw[p])
        if (o.node >= 0 && object_of[o.node] >= 0 && !votes[object_of[o.node]]++) touched.push_back(object_of[o.node]);
      int best = -1;
      for (int k : touched)
        if (best < 0 || votes[k] > votes[best] || (votes[k] == votes[best] && k < best)) best = k;
      for (int k : touched) votes[k] = 0;
      point_object[p] = best;
    }
  };
  vote_points();
  // Attach: a mask left out (too few 3D points to cluster, or alone) joins the object that holds at least half of
  // its 3D points, when that object has no mask in its view yet; best share first.
  if (opt.attach) {
    std::set<std::pair<int, int>> taken;  // (view, object)
    for (size_t i = 0; i < nodes.size(); ++i)
      if (object_of[i] >= 0) taken.insert({nodes[i].view, object_of[i]});
    struct Cand {
      double share;
      long points;
      int node, object;
    };
    std::vector<Cand> cands;
    for (size_t i = 0; i < nodes.size(); ++i) {
      const Node& n = nodes[i];
      if (object_of[i] >= 0 || n.points.empty() || n.drop.starts_with("background")) continue;
      std::map<int, long> votes;
      for (int p : n.points)
        if (point_object[p] >= 0) ++votes[point_object[p]];
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
      object_of[cd.node] = cd.object;
      ++sum.attached;
    }
    vote_points();
  }
  // Members of each object after attaching (node indices into `nodes`).
  std::vector<std::vector<int>> members(K);
  for (size_t i = 0; i < nodes.size(); ++i)
    if (object_of[i] >= 0) members[object_of[i]].push_back(int(i));

  // 3D spread of each object's voted points, relative to all points (robust: a few stray points do not count).
  std::vector<double> spread(K, 0);
  std::vector<long> obj_points(K, 0);
  {
    std::vector<std::vector<Eigen::Vector3d>> pts(K);
    std::vector<Eigen::Vector3d> all;
    // Over COLMAP's points only (--surface-spread is calibrated on them; lifted depth pixels sample the views'
    // visible surfaces evenly, which weighs large backgrounds differently).
    for (size_t p = 0; p < point_object.size(); ++p) {
      if (point_object[p] >= 0) ++obj_points[point_object[p]];
      if (p >= model.points.size()) continue;
      all.push_back(point_xyz[p]);
      if (point_object[p] >= 0) pts[point_object[p]].push_back(point_xyz[p]);
    }
    const double all_spread = robust_spread(all);
    for (int k = 0; k < K; ++k)
      if (all_spread > 0 && !pts[k].empty()) spread[k] = robust_spread(pts[k]) / all_spread;
  }

  // Objects: ids 1.. in cluster order (dropped surfaces removed), names by majority over their masks.
  std::vector<int> final_id(K, 0);
  for (int k = 0, next = 1; k < K; ++k) {
    const bool surface = spread[k] > opt.surface_spread;
    if (surface && opt.drop_surfaces) {
      for (int ni : members[k]) {
        Node& n = nodes[ni];
        n.drop = fmt::format("surface: 3D spread {:.2f} of the scene's (> --surface-spread {})", spread[k], opt.surface_spread);
      }
      ++sum.dropped_surface;
      continue;
    }
    AssociatedObject o;
    o.id = final_id[k] = next++;
    o.masks = int(members[k].size());
    std::vector<char> seen(s.views.size(), 0);
    std::vector<std::string> names;
    for (int ni : members[k]) {
      const Node& n = nodes[ni];
      o.views += !seen[n.view];
      seen[n.view] = 1;
      const std::string& stem = s.views[n.view].stem;
      for (int id : n.ids) {
        const std::string key = std::to_string(id);
        if (names_file.is_object() && names_file.contains(stem) && names_file[stem].is_object() && names_file[stem].contains(key) &&
            names_file[stem][key].is_string()) {
          names.push_back(names_file[stem][key].get<std::string>());
          break;
        }
        if (auto it = global_names.find(id); it != global_names.end()) {
          names.push_back(it->second);
          break;
        }
      }
    }
    o.name = names.empty() ? fmt::format("object {}", o.id) : most_common(names);
    o.points = obj_points[k];
    o.spread = spread[k];
    o.surface = surface;
    sum.objects.push_back(o);
  }

  // Output folder contents.
  const std::string suffix = fmt::format("{:08x}", std::random_device{}());
  const fs::path dst = in_place ? masks_dir : fs::absolute(opt.out_masks).lexically_normal();
  ensure_dir(dst.parent_path());
  const fs::path tmp = dst.parent_path() / fmt::format(".{}.associate-{}", dst.filename().string(), suffix);
  try {
    ensure_dir(tmp);
    json views = json::object(), dropped = json::array();
    Progress bar("associate: write masks", long(s.views.size()), opt.progress);
    for (auto& v : s.views) {
      bar.update(v.index + 1, v.name);
      if (labels[v.index].v.empty()) continue;
      std::map<int, int> new_id;  // root id -> final id (0 = dropped)
      json jv = json::object();
      for (auto& [r, ni] : view_node[v.index]) {
        const Node& n = nodes[ni];
        const int k = object_of[ni];
        new_id[r] = k >= 0 ? final_id[k] : 0;
        if (new_id[r] == 0) dropped.push_back({{"view", v.stem}, {"id", r}, {"ids", n.ids}, {"pixels", n.area},
                                              {"points", n.points.size()}, {"reason", n.drop}});
      }
      for (auto& [l, r] : view_root[v.index]) jv[std::to_string(l)] = new_id[r] ? json(new_id[r]) : json(nullptr);
      views[v.stem] = jv;
      LabelMap out = labels[v.index];
      for (auto& l : out.v) l = l ? uint16_t(new_id[l]) : 0;
      const fs::path png = tmp / (v.stem + ".png");
      ensure_dir(png.parent_path());
      save_label_png(png, out);
      const fs::path conf_file = in / (v.stem + ".conf.npy");
      std::vector<float> conf = std::move(reflattened_conf[v.index]);
      // The ramp replaces what a per-pixel confidence would say: only for SAM's per-mask scores (flat up to the
      // edge) and masks without any confidence; a per-pixel confidence (SAM2's, the user's) is kept as it is.
      const bool flat = sam_scores || !fs::exists(conf_file);
      if (conf.empty() && flat && opt.edge_ramp > 0 && fs::exists(conf_file)) {
        conf = read_npy(conf_file).to_float();
        if (conf.size() != size_t(v.width) * v.height)
          fail("{}: {} confidences for a {}x{} view", conf_file.string(), conf.size(), v.width, v.height);
      }
      if (flat && opt.edge_ramp > 0) edge_ramp_confidence(out, opt.edge_ramp, conf);
      if (!conf.empty())
        write_npy(tmp / (v.stem + ".conf.npy"), make_npy_f32({size_t(v.height), size_t(v.width)}, conf.data()));
      else if (fs::exists(conf_file))
        fs::copy_file(conf_file, tmp / (v.stem + ".conf.npy"));
    }
    bar.finish();
    json objects = json::object(), list = json::array();
    for (auto& o : sum.objects) {
      objects[std::to_string(o.id)] = o.name;
      list.push_back({{"id", o.id}, {"name", o.name}, {"views", o.views}, {"masks", o.masks}, {"points", o.points},
                      {"spread", std::round(o.spread * 1000) / 1000}, {"surface", o.surface}});
    }
    atomic_write_text(tmp / "objects.json", objects.dump(2) + "\n");
    // Where the per-view input is after this run (in place: masks/per_view, whatever it was read from).
    json report = {{"source", fs::absolute(in_place ? masks_dir / "per_view" : in).lexically_normal().string()},
                   {"colmap", images_file.string()},
                   {"options", {{"min_affinity", opt.min_affinity}, {"min_views", opt.min_views}, {"min_points", opt.min_points},
                                {"max_area", opt.max_area}, {"core_margin", opt.core_margin}, {"attach", opt.attach}, {"join_parts", opt.join_parts}, {"part_fraction", opt.part_fraction}, {"part_merge", opt.part_merge}, {"whole_pixels", opt.whole_pixels}, {"edge_ramp", opt.edge_ramp}, {"drop_surfaces", opt.drop_surfaces},
                                {"surface_spread", opt.surface_spread}, {"depth", bool(opt.depth)},
                                {"depth_stride", opt.depth_stride}, {"depth_tolerance", opt.depth_tolerance}}},
                   {"colmap_points", sum.colmap_points},
                   {"depth_points", sum.depth_points},
                   {"views_with_masks", sum.views_with_masks},
                   {"masks", sum.masks},
                   {"joined_parts", sum.joined_parts},
                   {"attached", sum.attached},
                   {"objects", list},
                   {"dropped", dropped},
                   {"ids", views}};
    atomic_write_text(tmp / "associate.json", report.dump(1) + "\n");
    if (in_place) {  // the per-view input, as it was, in masks/per_view/
      const fs::path keep = tmp / "per_view";
      if (associated) {
        fs::copy(in, keep, fs::copy_options::recursive);
      } else {
        ensure_dir(keep);
        for (auto& e : fs::directory_iterator(in)) {
          if (e.path().filename().string().starts_with(".")) continue;
          fs::copy(e.path(), keep / e.path().filename(), fs::copy_options::recursive);
        }
      }
      sum.backup_dir = masks_dir / "per_view";
    }
    const fs::path old = dst.parent_path() / fmt::format(".{}.old-{}", dst.filename().string(), suffix);
    std::error_code ec;
    if (fs::exists(dst)) {
      fs::rename(dst, old, ec);
      if (ec) fail("{}: cannot move the old folder aside ({})", dst.string(), ec.message());
    }
    fs::rename(tmp, dst, ec);
    if (ec) fail("{}: cannot move the associated masks into place ({})", dst.string(), ec.message());
    fs::remove_all(old, ec);
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
  return sum;
}

}  // namespace hgs::masks
