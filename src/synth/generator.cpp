// Orchestrates `hgs synth`: builds the world, renders every view (with gt/instances and gt/objects.json, the
// truth's names), simulates masks and features, samples SfM-like points with visibility tracks, writes the COLMAP
// model, labels for the held-out views (LERF-OVS JSON polygons and 3D-OVS PNGs) and a synth.json record.
// --mask-ids per-view / --mask-style sam add gt/mask_ids.json (what each per-view id truly is) and, for sam,
// sam/<stem>.json (SAM JSON, COCO RLE). Everything is written into a temporary folder beside the output and
// renamed at the end, so a failure leaves nothing behind. Each phase is one function, called in order by generate.
#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <set>

#include "core/error.h"
#include "core/fs.h"
#include "core/npy.h"
#include "core/progress.h"
#include "masks/flatten.h"
#include "masks/rle.h"
#include "scene/colmap.h"
#include "scene/text_embeddings.h"
#include "synth/language.h"
#include "synth/query_sets.h"
#include "synth/synth.h"
#include "synth/tracks.h"

namespace hgs::synth {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

uint64_t mix(uint64_t seed, uint64_t a, uint64_t b = 0) {
  uint64_t x = seed * 0x9E3779B97F4A7C15ULL + a * 0xD1B54A32D192ED03ULL + b;
  return splitmix64(x);
}

std::vector<float> noisy(const std::vector<float>& base, double rel, Rng& rng) {
  std::vector<float> v(base);
  double s = 0;
  const double k = rel / std::sqrt(double(v.size()));
  for (auto& x : v) {
    x += static_cast<float>(k * rng.normal());
    s += double(x) * x;
  }
  for (auto& x : v) x = static_cast<float>(x / std::sqrt(s));
  return v;
}

// --mask-ids per-view: the ids present in `mask` get a random permutation of 1..m; returns id -> true object.
json shuffle_ids(LabelMap& mask, uint64_t seed) {
  std::vector<int> present;
  {
    std::set<int> s(mask.v.begin(), mask.v.end());
    for (int l : s)
      if (l) present.push_back(l);
  }
  std::vector<int> ids(present.size());
  for (size_t i = 0; i < ids.size(); ++i) ids[i] = int(i) + 1;
  Rng rng(seed);
  for (size_t i = ids.size(); i > 1; --i) std::swap(ids[i - 1], ids[size_t(rng.integer(0, int(i) - 1))]);
  std::map<int, int> to;
  json truth = json::object();
  for (size_t i = 0; i < present.size(); ++i)
    to[present[i]] = ids[i], truth[std::to_string(ids[i])] = {{"object", present[i]}};
  for (auto& l : mask.v)
    if (l) l = uint16_t(to[l]);
  return truth;
}

void validate(const SynthOptions& o) {
  if (o.world != "realistic" && o.world != "simple") fail("--world: unknown value '{}' (realistic or simple)", o.world);
  if (o.mask_ids != "consistent" && o.mask_ids != "per-view")
    fail("--mask-ids: unknown value '{}' (consistent or per-view)", o.mask_ids);
  if (o.mask_style != "label" && o.mask_style != "sam")
    fail("--mask-style: unknown value '{}' (label or sam)", o.mask_style);
  if (o.views < 2 || o.views > 10000) fail("--views: must be between 2 and 10000, got {}", o.views);
  if (o.width < 16 || o.height < 16 || o.width > 8192 || o.height > 8192)
    fail("--width/--height: must be between 16 and 8192, got {}x{}", o.width, o.height);
  if (o.points < 0 || o.points > 10000000) fail("--points: must be between 0 and 10000000, got {}", o.points);
  if (o.feature_dim < 1 || o.feature_dim > 4096)
    fail("--feature-dim: must be between 1 and 4096, got {}", o.feature_dim);
  noise_level(o.noise);
  for (auto [name, r] : {std::pair<const char*, double>{"--miss-rate", o.miss_rate},
                         {"--small-miss-rate", o.small_miss_rate},
                         {"--merge-rate", o.merge_rate},
                         {"--split-rate", o.split_rate}})
    if (r > 1) fail("{}: a rate between 0 and 1, got {}", name, r);
}

// The surfaces' concepts: index 0 is the sky / empty background, then every distinct surface concept.
struct Concepts {
  std::vector<std::string> names;
  std::vector<std::vector<float>> vectors;  // [C][feature_dim] concept_vector of each name
  // Background surfaces: every concept that is no object ("sky" = nothing hit is none).
  std::vector<int> surfaces;                 // indices into names
  std::vector<int> surface_of;               // per concept c: 1 + the surface's index for c, else 0
  std::vector<float> context;                // [feature_dim] the preset's context phrase
  std::vector<std::vector<float>> contents;  // realistic world: [C][feature_dim] image_content of each concept
};

Concepts make_concepts(const World& world, const SynthOptions& opt) {
  Concepts cc;
  cc.names = {"sky"};
  for (auto& p : world.prims)
    if (std::find(cc.names.begin(), cc.names.end(), p.concept_name) == cc.names.end())
      cc.names.push_back(p.concept_name);
  for (auto& c : cc.names) cc.vectors.push_back(concept_vector(c, opt.feature_dim));
  cc.surface_of.assign(cc.names.size(), 0);
  for (size_t c = 1; c < cc.names.size(); ++c) {
    bool object = false;
    for (auto& o : world.objects) object |= o.name == cc.names[c];
    if (!object) cc.surfaces.push_back(int(c)), cc.surface_of[c] = int(cc.surfaces.size());
  }
  const std::string context_phrase = opt.preset == "room" ? "a photo of a room" : "a photo of a tabletop";
  cc.context = concept_vector(context_phrase, opt.feature_dim);
  if (opt.world == "realistic")
    for (auto& c : cc.names) cc.contents.push_back(image_content(lexeme_of(c), opt.feature_dim));
  return cc;
}

// What every phase of one generation reads.
struct Generation {
  const SynthOptions& opt;
  const fs::path& tmp;  // the temporary output folder
  const World& world;
  const Concepts& concepts;
  const NoiseLevel nl;
  const Intrinsics cam;
  const int K;  // objects
  const bool sam_style, per_view;
  std::vector<char> split;         // [K] --mask-style sam: objects that SAM also cuts into two halves
  std::vector<int> part_id;        // [K] label style: the mask id of object k's part, 0 = the object is not split
  json mask_ids = json::object();  // per view: id in masks/<stem>.png -> what it truly is
  std::set<int> surface_used;      // --mask-style sam: concepts of the surfaces some view has a mask of
  bool realistic = false;
  int first_free_id = 0;                // realistic world: the first id after the surfaces' pieces and the parts
  std::unique_ptr<Sam2Simulator> sam2;  // realistic world, label style: the tracks over the capture order
};

std::string stem_of(const RenderedView& rv) { return rv.name.substr(0, rv.name.size() - 4); }

// Renders every view; writes images/, gt/instances/ and (--depth) gt/depth/.
std::vector<RenderedView> render_views(const Generation& g) {
  const SynthOptions& opt = g.opt;
  auto poses = make_poses(g.world, opt.views, opt.seed);
  std::vector<RenderedView> views(opt.views);
  Progress bar("synth: render", opt.views, opt.progress);
  for (int i = 0; i < opt.views; ++i) {
    views[i] = render_view(g.world, g.cam, poses[i].first, poses[i].second, opt.supersample, g.concepts.names);
    views[i].name = fmt::format("frame_{:05d}.png", i + 1);
    save_png(g.tmp / "images" / views[i].name, views[i].rgb);
    save_label_png(g.tmp / "gt" / "instances" / views[i].name, views[i].instances);
    if (opt.write_depth) {
      const std::string stem = fs::path(views[i].name).replace_extension().string();
      write_npy(g.tmp / "gt" / "depth" / (stem + ".npy"),
                make_npy_f32({size_t(opt.height), size_t(opt.width)}, views[i].depth.data()));
    }
    bar.update(i + 1);
  }
  bar.finish();
  return views;
}

// One entry of SAM's automatic mask generator JSON (COCO RLE) for a mask; sm receives its RLE and scores.
json sam_entry(const SamMask& mask, int W, int H, masks::SourceMask& sm) {
  sm.rle = masks::rle_encode(mask.inside, W, H);
  sm.predicted_iou = mask.predicted_iou;
  sm.stability_score = mask.stability_score;
  int x0 = W, y0 = H, x1 = -1, y1 = -1;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      if (mask.inside[size_t(y) * W + x])
        x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x), y1 = std::max(y1, y);
  return {{"segmentation", {{"size", {H, W}}, {"counts", masks::rle_counts_to_string(sm.rle.counts)}}},
          {"area", masks::rle_area(sm.rle)},
          {"bbox", {x0, y0, x1 - x0 + 1, y1 - y0 + 1}},
          {"predicted_iou", mask.predicted_iou},
          {"point_coords", {{(x0 + x1) / 2, (y0 + y1) / 2}}},
          {"stability_score", mask.stability_score},
          {"crop_box", {0, 0, W, H}}};
}

// --mask-style sam, one view: sam/<stem>.json, the flattened masks/<stem>.png and its confidence; the truth of
// every id goes to g.mask_ids.
void write_sam_view(Generation& g, const RenderedView& rv, uint64_t seed) {
  const std::string stem = stem_of(rv);
  const int K = g.K;
  std::vector<SamMask> sam = simulate_sam_masks(rv, g.cam, g.world, g.split, g.nl, seed);
  const int W = rv.rgb.width, H = rv.rgb.height;
  json list = json::array();
  std::vector<masks::SourceMask> src;
  json ids = json::object();
  for (size_t m = 0; m < sam.size(); ++m) {
    masks::SourceMask sm;
    list.push_back(sam_entry(sam[m], W, H, sm));
    src.push_back(std::move(sm));
    const int e = sam[m].entity;
    json truth = {{"entity", e}};
    if (e <= K) truth["object"] = e;
    else if (e <= 3 * K) truth["object"] = (e - K - 1) / 2 + 1, truth["part"] = (e - K - 1) % 2 + 1;
    else truth["object"] = 0, truth["surface"] = g.concepts.names[e - 3 * K], g.surface_used.insert(e - 3 * K);
    ids[std::to_string(g.per_view ? int(m) + 1 : e)] = truth;
  }
  atomic_write_text(g.tmp / "sam" / (stem + ".json"), list.dump() + "\n");
  masks::Flattened f = masks::flatten_masks(src, W, H);  // ids 1 + list position
  if (!g.per_view)
    for (auto& l : f.labels.v)
      if (l) l = uint16_t(sam[l - 1].entity);
  save_label_png(g.tmp / "masks" / (stem + ".png"), f.labels);
  write_npy(g.tmp / "masks" / (stem + ".conf.npy"),
            make_npy_f32({size_t(H), size_t(W)},
                         f.confidence.empty() ? std::vector<float>(size_t(W) * H, 1.f).data() : f.confidence.data()));
  g.mask_ids[stem] = ids;
}

// A label-style view's masks/<stem>.png and, when there is confidence noise, its masks/<stem>.conf.npy (float16).
void write_label_mask(const Generation& g, const std::string& stem, const LabelMap& mask,
                      const std::vector<float>& conf) {
  save_label_png(g.tmp / "masks" / (stem + ".png"), mask);
  if (!conf.empty())
    write_npy(g.tmp / "masks" / (stem + ".conf.npy"),
              make_npy_f16({size_t(g.opt.height), size_t(g.opt.width)}, conf.data()));
}

// --mask-style label, view i: the simulated SAM2 masks/<stem>.png and its confidence (per-view ids: shuffled,
// the truth of every id in g.mask_ids).
void write_label_view(Generation& g, int i, const RenderedView& rv) {
  const std::string stem = stem_of(rv);
  const SynthOptions& opt = g.opt;
  const int K = g.K;
  LabelMap mask;
  std::vector<float> conf;
  simulate_masks(rv.instances, g.nl, K, mix(opt.seed, 1, i), mask, conf);
  if (opt.surface_masks)
    for (size_t p = 0; p < mask.v.size(); ++p)
      if (mask.v[p] == 0 && rv.instances.v[p] == 0 && g.concepts.surface_of[rv.concept_id[p]])
        mask.v[p] = static_cast<uint16_t>(K + g.concepts.surface_of[rv.concept_id[p]]);
  // Parts: where the mask still shows the object itself, its upper half (world z >= the object's centre: a lid, a
  // cap, a head, seen from every view above the table) takes the part's id.
  std::map<int, int> object_of_part;
  for (int k = 1; k <= K; ++k) {
    const int part = g.part_id[k - 1];
    if (!part) continue;
    object_of_part[part] = k;
    const double split_z = g.world.objects[k - 1].position.z();
    for (int y = 0; y < mask.height; ++y)
      for (int x = 0; x < mask.width; ++x) {
        const size_t p = size_t(y) * mask.width + x;
        if (mask.v[p] == k && rv.instances.v[p] == k && pixel_world_point(rv, g.cam, x, y).z() >= split_z)
          mask.v[p] = static_cast<uint16_t>(part);
      }
  }
  if (g.per_view) {
    g.mask_ids[stem] = shuffle_ids(mask, mix(opt.seed, 5, i));
    for (auto& [id, truth] : g.mask_ids[stem].items()) {  // a surface's id K + j is no object; a part's is
      const int e = truth["object"].get<int>();
      if (object_of_part.count(e)) truth = {{"object", object_of_part[e]}, {"part", 1}};
      else if (e > K) truth = {{"object", 0}, {"surface", g.concepts.names[g.concepts.surfaces[e - K - 1]]}};
    }
  }
  write_label_mask(g, stem, mask, conf);
}

// Realistic world, label style, view i (in capture order): the SAM2-like tracks' mask (tracks.h), its confidence
// and what every id truly is (g.mask_ids, also with consistent ids: a track re-born or swapped shows another
// object than its name says).
void write_tracked_view(Generation& g, int i, const RenderedView& rv) {
  const std::string stem = stem_of(rv);
  LabelMap mask;
  std::vector<float> conf;
  std::map<int, IdTruth> truth;
  g.sam2->next(i, mask, conf, truth);
  auto describe = [](const IdTruth& t) {
    json j = {{"object", t.object}, {"kind", t.kind}};
    if (t.kind == "surface") j["surface"] = t.surface, j["piece"] = t.piece;
    if (t.kind == "part") j["part"] = 1;
    return j;
  };
  json ids = json::object();
  if (g.per_view) {
    const json shuffled = shuffle_ids(mask, mix(g.opt.seed, 5, i));
    for (auto& [id, was] : shuffled.items()) ids[id] = describe(truth.at(was["object"].get<int>()));
  } else {
    for (auto& [id, t] : truth) ids[std::to_string(id)] = describe(t);
  }
  g.mask_ids[stem] = ids;
  write_label_mask(g, stem, mask, conf);
}

// Simulated SAM2 masks and confidences (or SAM-style overlapping masks with --mask-style sam) and CLIP-like
// features of every view.
void write_masks_and_features(Generation& g, const std::vector<RenderedView>& views) {
  const SynthOptions& opt = g.opt;
  Progress bar("synth: masks+features", opt.views, opt.progress);
  if (g.realistic && !g.sam_style)
    g.sam2 = std::make_unique<Sam2Simulator>(g.world, g.cam, views,
                                             opt.surface_masks ? g.concepts.surfaces : std::vector<int>(),
                                             g.concepts.names, g.part_id, g.nl, g.first_free_id, mix(opt.seed, 9));
  for (int i = 0; i < opt.views; ++i) {
    if (g.sam_style) write_sam_view(g, views[i], mix(opt.seed, 6, i));
    else if (g.sam2) write_tracked_view(g, i, views[i]);
    else write_label_view(g, i, views[i]);
    int gh, gw;
    auto feat = g.realistic ? simulate_dense_features(views[i], g.concepts.contents, g.nl, opt.feature_dim,
                                                      mix(opt.seed, 2, i), gh, gw)
                            : simulate_features(views[i], g.concepts.vectors, g.concepts.context, g.nl.feature,
                                                opt.feature_dim, mix(opt.seed, 2, i), gh, gw);
    write_npy(g.tmp / "features" / (stem_of(views[i]) + ".npy"),
              make_npy_f16({size_t(gh), size_t(gw), size_t(opt.feature_dim)}, feat.data()));
    bar.update(i + 1);
  }
  bar.finish();
}

// Names of the ids in the masks (the training input): masks/objects.json, unless the ids are per-view (they name
// nothing; their truth is in gt/mask_ids.json).
void write_mask_names(const Generation& g) {
  if (g.per_view) return;
  const int K = g.K;
  const Concepts& cc = g.concepts;
  json names = json::object();
  if (g.sam2) {
    for (auto& [id, name] : g.sam2->names()) names[std::to_string(id)] = name;
    atomic_write_text(g.tmp / "masks" / "objects.json", names.dump(2) + "\n");
    return;
  }
  for (auto& o : g.world.objects) names[std::to_string(o.id)] = o.name;
  if (g.opt.surface_masks && !g.sam_style)
    for (size_t j = 0; j < cc.surfaces.size(); ++j) names[std::to_string(K + 1 + int(j))] = cc.names[cc.surfaces[j]];
  for (auto& o : g.world.objects)
    if (g.part_id[o.id - 1]) names[std::to_string(g.part_id[o.id - 1])] = fmt::format("{} (part)", o.name);
  if (g.sam_style) {
    for (auto& o : g.world.objects)
      if (g.split[o.id - 1])
        for (int h = 1; h <= 2; ++h)
          names[std::to_string(K + 2 * (o.id - 1) + h)] = fmt::format("{} (part {})", o.name, h);
    for (size_t c = 1; c < cc.names.size(); ++c)
      if (g.surface_used.count(int(c))) names[std::to_string(3 * K + int(c))] = cc.names[c];
  }
  atomic_write_text(g.tmp / "masks" / "objects.json", names.dump(2) + "\n");
}

// Names of the ids in gt/instances (the objects; surfaces are 0 there): gt/objects.json, read by eval only.
void write_truth_names(const Generation& g) {
  json names = json::object();
  for (auto& o : g.world.objects) names[std::to_string(o.id)] = o.name;
  atomic_write_text(g.tmp / "gt" / "objects.json", names.dump(2) + "\n");
}

// Text embeddings: class names (concept + small noise), synonyms (more noise), background surfaces,
// distractors (pool names not in the scene, plus a few unrelated phrases) and LERF's canonical phrases.
void write_text_embeddings(const Generation& g) {
  const int D = g.opt.feature_dim;
  const Concepts& cc = g.concepts;
  if (g.realistic) {  // the lexicon's embeddings (language.h) and the query sets (query_sets.h)
    std::vector<std::string> surfaces, distract = g.world.unused_names;
    for (int c : cc.surfaces) surfaces.push_back(cc.names[c]);
    for (const char* d : {"violin", "sports car", "umbrella", "laptop computer"}) distract.push_back(d);
    json te, queries;
    realistic_text(g.world, surfaces, distract, D, te, queries);
    hgs::write_text_embeddings(g.tmp / "text_embeddings.json", te);
    atomic_write_text(g.tmp / "gt" / "queries.json", queries.dump(2) + "\n");
    return;
  }
  Rng rng(mix(g.opt.seed, 3));
  json te = json::object();
  for (auto& o : g.world.objects) te[o.name] = float_array(noisy(concept_vector(o.name, D), 0.15, rng));
  for (auto& [syn, name] : g.world.synonyms) te[syn] = float_array(noisy(concept_vector(name, D), 0.45, rng));
  for (size_t c = 1; c < cc.names.size(); ++c)
    if (!te.contains(cc.names[c])) te[cc.names[c]] = float_array(noisy(cc.vectors[c], 0.15, rng));
  std::vector<std::string> distract = g.world.unused_names;
  for (const char* d : {"violin", "sports car", "umbrella", "laptop computer"}) distract.push_back(d);
  for (auto& d : distract) te[d] = float_array(noisy(concept_vector(d, D), 0.15, rng));
  for (const char* c : kCanonicalPhrases) {
    auto own = concept_vector(c, D);
    std::vector<float> v(D);
    for (int d = 0; d < D; ++d) v[d] = cc.context[d] + 0.6f * own[d];
    te[c] = float_array(noisy(v, 0.0, rng));
  }
  hgs::write_text_embeddings(g.tmp / "text_embeddings.json", te);
}

// Camera-space point at the centre of pixel (x, y) at depth z. Not inlined: the point is rounded before the
// caller subtracts the translation (no fused multiply-add across the two), which the scenes' bytes rely on.
[[gnu::noinline]] Vec3 pixel_point(const Intrinsics& cam, int x, int y, float z) {
  return Vec3((x + 0.5 - cam.cx) / cam.fx * z, (y + 0.5 - cam.cy) / cam.fy * z, z);
}

// The views that see world point X at their depth there (so occluded views are not in it): (view, pixel).
std::vector<std::pair<int, Eigen::Vector2d>> point_track(const Generation& g, const std::vector<RenderedView>& views,
                                                         const Vec3& X, double sigma) {
  const Intrinsics& K_ = g.cam;
  const int W = g.opt.width, H = g.opt.height;
  std::vector<std::pair<int, Eigen::Vector2d>> obs;
  for (int u = 0; u < g.opt.views; ++u) {
    Vec3 q = views[u].R * X + views[u].t;
    if (q.z() <= 1e-6) continue;
    double px = K_.fx * q.x() / q.z() + K_.cx, py = K_.fy * q.y() / q.z() + K_.cy;
    if (px < 0 || py < 0 || px >= W || py >= H) continue;
    float dz = views[u].depth[size_t(py) * W + size_t(px)];
    if (dz <= 0 || std::abs(q.z() - dz) > 0.01 * dz + 4 * sigma) continue;
    obs.emplace_back(u, Eigen::Vector2d(px, py));
  }
  return obs;
}

// SfM-like points: random visible surface samples with position noise, each with its track (point_track), added
// to the model's points and its images' keypoints.
void place_points(const Generation& g, const std::vector<RenderedView>& views, ColmapModel& model) {
  const SynthOptions& opt = g.opt;
  const Intrinsics& K_ = g.cam;
  Rng rng(mix(opt.seed, 4));
  const double sigma = (opt.preset == "room" ? 0.004 : 0.0015) * (g.nl.feature > 0 ? 1.0 : 0.5);
  const int W = opt.width, H = opt.height;
  long attempts = 0;
  while (static_cast<int>(model.points.size()) < opt.points && attempts < 20L * opt.points + 1000) {
    ++attempts;
    int v = rng.integer(0, opt.views - 1), x = rng.integer(0, W - 1), y = rng.integer(0, H - 1);
    const RenderedView& rv = views[v];
    float z = rv.depth[size_t(y) * W + x];
    if (z <= 0) continue;
    Vec3 X = rv.R.transpose() * (pixel_point(K_, x, y, z) - rv.t);
    X += sigma * Vec3(rng.normal(), rng.normal(), rng.normal());
    ColmapPoint p;
    p.id = model.points.size() + 1;
    p.xyz = X;
    for (int c = 0; c < 3; ++c)
      p.rgb[c] = static_cast<uint8_t>(std::lround(rv.rgb.px[(size_t(y) * W + x) * 3 + c] * 255));
    p.error = rng.uniform(0.3, 1.2);
    const auto obs = point_track(g, views, X, sigma);
    if (obs.size() < 2) continue;
    for (auto& [u, xy] : obs) {
      ColmapImage& im = model.images[u];
      p.track.emplace_back(im.id, static_cast<int32_t>(im.xys.size()));
      im.xys.push_back(xy);
      im.point3d_ids.push_back(static_cast<int64_t>(p.id));
    }
    model.points.push_back(std::move(p));
  }
  if (static_cast<int>(model.points.size()) < opt.points)
    fail("synth: could only place {} of {} points seen by two views (too few views?)", model.points.size(), opt.points);
}

// The COLMAP model: one pinhole camera, the views' poses and the SfM-like points; sparse/0/*.bin.
void write_colmap_model(const Generation& g, const std::vector<RenderedView>& views) {
  const SynthOptions& opt = g.opt;
  const Intrinsics& K_ = g.cam;
  ColmapModel model;
  model.cameras[1] =
      ColmapCamera{1, "PINHOLE", uint64_t(opt.width), uint64_t(opt.height), {K_.fx, K_.fy, K_.cx, K_.cy}};
  for (int i = 0; i < opt.views; ++i) {
    ColmapImage im;
    im.id = i + 1;
    im.qvec = rotmat_to_qvec(views[i].R);
    im.tvec = views[i].t;
    im.camera_id = 1;
    im.name = views[i].name;
    model.images.push_back(im);
  }
  place_points(g, views, model);
  write_colmap_bin(g.tmp / "sparse" / "0", model);
}

// Labels of held-out view i: 3D-OVS segmentations/<i>/<class>.png for every surface and object, and the LERF-OVS
// polygons label/<stem>.json of the visible objects.
void write_view_labels(const Generation& g, int i, const RenderedView& rv) {
  const SynthOptions& opt = g.opt;
  auto save_segmentation = [&](const std::string& cls, const std::vector<uint8_t>& inside) {
    Image seg(opt.width, opt.height, 1);
    for (size_t p = 0; p < inside.size(); ++p) seg.px[p] = inside[p] ? 1.f : 0.f;
    save_png(g.tmp / "segmentations" / std::to_string(i) / (cls + ".png"), seg);
  };
  for (int c : g.concepts.surfaces) {
    std::vector<uint8_t> inside(rv.instances.v.size());
    for (size_t p = 0; p < inside.size(); ++p) inside[p] = rv.concept_id[p] == c && rv.instances.v[p] == 0;
    save_segmentation(g.concepts.names[c], inside);
  }
  json objs = json::array();
  for (auto& o : g.world.objects) {
    std::vector<uint8_t> inside(rv.instances.v.size());
    size_t cnt = 0;
    for (size_t p = 0; p < inside.size(); ++p) cnt += inside[p] = rv.instances.v[p] == o.id;
    save_segmentation(o.name, inside);
    if (!cnt) continue;
    for (auto& poly : trace_polygons(inside, opt.width, opt.height)) {
      int x1 = opt.width, y1 = opt.height, x2 = 0, y2 = 0;
      json pts = json::array();
      for (auto [x, y] : poly) {
        x1 = std::min(x1, x);
        y1 = std::min(y1, y);
        x2 = std::max(x2, x);
        y2 = std::max(y2, y);
        pts.push_back({x, y});
      }
      objs.push_back({{"category", o.name}, {"bbox", {x1, y1, x2, y2}}, {"segmentation", pts}});
    }
  }
  json label = {{"info", {{"name", rv.name}, {"width", opt.width}, {"height", opt.height}}}, {"objects", objs}};
  atomic_write_text(g.tmp / "label" / (stem_of(rv) + ".json"), label.dump() + "\n");
}

// Labels for the held-out views (every 8th view, the LLFF split hgs uses without test.txt).
void write_heldout_labels(const Generation& g, const std::vector<RenderedView>& views) {
  // 3D-OVS classes: the objects and, as the real 3D-OVS labels every surface, the background surfaces
  // (table, floor, walls: every concept that is no object; "sky" = nothing hit stays unlabelled).
  std::vector<std::string> seg_classes;
  for (auto& o : g.world.objects) seg_classes.push_back(o.name);
  for (int c : g.concepts.surfaces) seg_classes.push_back(g.concepts.names[c]);
  std::sort(seg_classes.begin(), seg_classes.end());
  std::string ctext;
  for (auto& c : seg_classes) ctext += c + "\n";
  atomic_write_text(g.tmp / "segmentations" / "classes.txt", ctext);
  for (int i = 0; i < g.opt.views; i += 8) write_view_labels(g, i, views[i]);
}

// synth.json: the record of what was generated.
void write_record(const Generation& g) {
  const SynthOptions& opt = g.opt;
  const NoiseLevel& nl = g.nl;
  json objs = json::array();
  for (auto& o : g.world.objects)
    objs.push_back({{"id", o.id},
                    {"name", o.name},
                    {"shape", o.shape},
                    {"position", {o.position.x(), o.position.y(), o.position.z()}}});
  json syn = json::object();
  for (auto& [s, n] : g.world.synonyms) syn[s] = n;
  json meta = {{"generator", "hgs synth " HGS_VERSION},
               {"preset", opt.preset},
               {"seed", opt.seed},
               {"views", opt.views},
               {"width", opt.width},
               {"height", opt.height},
               {"points", opt.points},
               {"noise", opt.noise},
               {"noise_params",
                {{"miss", nl.miss},
                 {"jitter_px", nl.jitter},
                 {"merge", nl.merge},
                 {"swap", nl.swap},
                 {"confidence_noise", nl.conf_noise},
                 {"feature_noise", nl.feature},
                 {"small_object_miss", nl.small_miss},
                 {"split", nl.split}}},
               {"feature_dim", opt.feature_dim},
               {"feature_patch", 16},  // the simple world's; the realistic one's grid is "feature_grid"
               {"objects", objs},
               {"synonyms", syn},
               {"distractors", g.world.unused_names},
               {"background_concepts", std::vector<std::string>(g.concepts.names.begin() + 1, g.concepts.names.end())}};
  if (g.per_view) meta["mask_ids"] = opt.mask_ids;  // only when not the default, so default scenes keep their bytes
  if (g.sam_style) meta["mask_style"] = opt.mask_style;
  meta["surface_masks"] = opt.surface_masks;
  if (opt.objects_only) meta["objects_only"] = true;
  json parts = json::object();  // mask id of each split object's part
  for (int k = 0; k < g.K; ++k)
    if (g.part_id[k]) parts[std::to_string(g.part_id[k])] = k + 1;
  if (!parts.empty()) meta["parts"] = parts;
  if (opt.write_depth) meta["depth"] = "gt/depth";
  if (g.realistic) {  // the simple world's record keeps its bytes
    meta["world"] = "realistic";
    meta["noise_params"]["tracks"] = {
        {"lose", nl.lose},     {"occluded_lose", nl.occluded_lose}, {"run_mean", nl.run_mean},
        {"reborn", nl.reborn}, {"edge_bias_px", nl.edge_bias},      {"surface_pieces", nl.pieces}};
    meta["noise_params"]["language"] = {{"view_bias", nl.view_bias},
                                        {"confusion", nl.confusion},
                                        {"patch_noise", nl.patch_noise}};
    meta["queries"] = "gt/queries.json";
    meta.erase("feature_patch");
    meta["feature_grid_short_side"] = kGridShort;
  }
  atomic_write_text(g.tmp / "synth.json", meta.dump(2) + "\n");
}

}  // namespace

void generate(const fs::path& out, const SynthOptions& options) {
  validate(options);
  SynthOptions opt = options;
  if (opt.objects_only) opt.surface_masks = false;
  if (fs::exists(out) && (!fs::is_directory(out) || !fs::is_empty(out)))
    fail("{}: output folder exists and is not empty (choose a new folder)", out.string());
  const World world = make_world(opt.preset, opt.objects, opt.seed);
  const Concepts concepts = make_concepts(world, opt);
  fs::path parent = fs::absolute(out).parent_path();
  ensure_dir(parent);
  fs::path tmp =
      parent / (out.filename().string() + fmt::format(".tmp{:x}", mix(opt.seed, std::random_device{}()) & 0xffffff));
  Generation g{opt,
               tmp,
               world,
               concepts,
               noise_of(opt),
               make_intrinsics(opt.width, opt.height),
               opt.objects,
               opt.mask_style == "sam",
               opt.mask_ids == "per-view",
               std::vector<char>(opt.objects, 0),
               std::vector<int>(opt.objects, 0),
               json::object(),
               {},
               false,
               0,
               nullptr};
  for (int k = 0; k < g.K; ++k) g.split[k] = mix(opt.seed, 7, k) & 1;
  // Label style: the objects whose part SAM cut off (and SAM2 tracked as an object), ids after the surfaces.
  g.realistic = opt.world == "realistic";
  const int pieces = g.realistic ? std::max(1, g.nl.pieces) : 1;
  int next_id = g.K + (opt.surface_masks ? int(concepts.surfaces.size()) * pieces : 0) + 1;
  for (int k = 0; k < g.K && !g.sam_style; ++k)
    if (double(mix(opt.seed, 8, k) >> 11) * 0x1.0p-53 < g.nl.split) g.part_id[k] = next_id++;
  g.first_free_id = next_id;
  try {
    ensure_dir(tmp);
    const std::vector<RenderedView> views = render_views(g);
    write_masks_and_features(g, views);
    write_mask_names(g);
    write_truth_names(g);
    if (g.per_view || g.sam_style || g.sam2) atomic_write_text(tmp / "gt" / "mask_ids.json", g.mask_ids.dump(1) + "\n");
    write_text_embeddings(g);
    write_colmap_model(g, views);
    write_heldout_labels(g, views);
    write_record(g);
    std::error_code ec;
    if (fs::exists(out)) fs::remove(out, ec);  // an empty folder
    fs::rename(tmp, out, ec);
    if (ec) fail("{}: cannot move the generated scene into place ({})", out.string(), ec.message());
  } catch (...) {
    std::error_code ec;
    fs::remove_all(tmp, ec);
    throw;
  }
}

}  // namespace hgs::synth
