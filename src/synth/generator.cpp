// Orchestrates `hgs synth`: builds the world, renders every view, simulates masks and features, samples
// SfM-like points with visibility tracks, writes the COLMAP model, labels for the held-out views (LERF-OVS
// JSON polygons and 3D-OVS PNGs) and a synth.json record. --mask-ids per-view / --mask-style sam add
// gt/mask_ids.json (what each per-view id truly is) and, for sam, sam/<stem>.json (SAM JSON, COCO RLE). Everything is written into a temporary folder
// beside the output and renamed at the end, so a failure leaves nothing behind.
#include <algorithm>
#include <cmath>
#include <map>
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
#include "synth/synth.h"

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
  for (auto& x : v) { x += static_cast<float>(k * rng.normal()); s += double(x) * x; }
  for (auto& x : v) x = static_cast<float>(x / std::sqrt(s));
  return v;
}

json float_array(const std::vector<float>& v) {
  json a = json::array();
  for (float x : v) a.push_back(std::round(double(x) * 1e6) / 1e6);
  return a;
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
  for (size_t i = 0; i < present.size(); ++i) to[present[i]] = ids[i], truth[std::to_string(ids[i])] = {{"object", present[i]}};
  for (auto& l : mask.v)
    if (l) l = uint16_t(to[l]);
  return truth;
}

void validate(const SynthOptions& o) {
  if (o.mask_ids != "consistent" && o.mask_ids != "per-view") fail("--mask-ids: unknown value '{}' (consistent or per-view)", o.mask_ids);
  if (o.mask_style != "label" && o.mask_style != "sam") fail("--mask-style: unknown value '{}' (label or sam)", o.mask_style);
  if (o.views < 2 || o.views > 10000) fail("--views: must be between 2 and 10000, got {}", o.views);
  if (o.width < 16 || o.height < 16 || o.width > 8192 || o.height > 8192)
    fail("--width/--height: must be between 16 and 8192, got {}x{}", o.width, o.height);
  if (o.points < 0 || o.points > 10000000) fail("--points: must be between 0 and 10000000, got {}", o.points);
  if (o.feature_dim < 1 || o.feature_dim > 4096) fail("--feature-dim: must be between 1 and 4096, got {}", o.feature_dim);
  noise_level(o.noise);
}

}  // namespace

void generate(const fs::path& out, const SynthOptions& opt) {
  validate(opt);
  if (fs::exists(out) && (!fs::is_directory(out) || !fs::is_empty(out)))
    fail("{}: output folder exists and is not empty (choose a new folder)", out.string());
  const NoiseLevel nl = noise_level(opt.noise);
  World world = make_world(opt.preset, opt.objects, opt.seed);
  const int K = opt.objects;

  // Concepts: index 0 is the sky / empty background, then every distinct surface concept.
  std::vector<std::string> concept_names = {"sky"};
  for (auto& p : world.prims)
    if (std::find(concept_names.begin(), concept_names.end(), p.concept_name) == concept_names.end()) concept_names.push_back(p.concept_name);
  std::vector<std::vector<float>> concepts;
  for (auto& c : concept_names) concepts.push_back(concept_vector(c, opt.feature_dim));
  // Background surfaces: every concept that is no object ("sky" = nothing hit is none). surface_of[c] = 1 + the
  // surface's index for concept c, else 0.
  std::vector<int> surface_concepts;  // indices into concept_names
  std::vector<int> surface_of(concept_names.size(), 0);
  for (size_t c = 1; c < concept_names.size(); ++c) {
    bool object = false;
    for (auto& o : world.objects) object |= o.name == concept_names[c];
    if (!object) surface_concepts.push_back(int(c)), surface_of[c] = int(surface_concepts.size());
  }
  const std::string context_phrase = opt.preset == "room" ? "a photo of a room" : "a photo of a tabletop";
  std::vector<float> context = concept_vector(context_phrase, opt.feature_dim);

  const Intrinsics K_ = make_intrinsics(opt.width, opt.height);
  auto poses = make_poses(world, opt.views, opt.seed);

  fs::path parent = fs::absolute(out).parent_path();
  ensure_dir(parent);
  fs::path tmp = parent / (out.filename().string() + fmt::format(".tmp{:x}", mix(opt.seed, std::random_device{}()) & 0xffffff));
  try {
    ensure_dir(tmp);
    std::vector<RenderedView> views(opt.views);
    {
      Progress bar("synth: render", opt.views, opt.progress);
      for (int i = 0; i < opt.views; ++i) {
        views[i] = render_view(world, K_, poses[i].first, poses[i].second, opt.supersample, concept_names);
        views[i].name = fmt::format("frame_{:05d}.png", i + 1);
        save_png(tmp / "images" / views[i].name, views[i].rgb);
        save_label_png(tmp / "gt" / "instances" / views[i].name, views[i].instances);
        if (opt.write_depth) {
          const std::string stem = fs::path(views[i].name).replace_extension().string();
          write_npy(tmp / "gt" / "depth" / (stem + ".npy"),
                    make_npy_f32({size_t(opt.height), size_t(opt.width)}, views[i].depth.data()));
        }
        bar.update(i + 1);
      }
      bar.finish();
    }
    // Simulated SAM2 masks and confidences (or SAM-style overlapping masks with --mask-style sam).
    const bool sam_style = opt.mask_style == "sam", per_view = opt.mask_ids == "per-view";
    std::vector<char> split(K, 0);  // --mask-style sam: objects that SAM also cuts into two halves
    for (int k = 0; k < K; ++k) split[k] = mix(opt.seed, 7, k) & 1;
    json mask_ids = json::object();  // per view: id in masks/<stem>.png -> what it truly is
    std::set<int> surface_used;
    auto write_sam_view = [&](const fs::path& dir, const std::string& stem, const RenderedView& rv, const Intrinsics& Kin,
                              const World& wd, const std::vector<char>& spl, const NoiseLevel& nlv, uint64_t seed, bool pv,
                              json& ids_out) {
      std::vector<SamMask> sam = simulate_sam_masks(rv, Kin, wd, spl, nlv, seed);
      const int W = rv.rgb.width, H = rv.rgb.height;
      json list = json::array();
      std::vector<masks::SourceMask> src;
      json ids = json::object();
      for (size_t m = 0; m < sam.size(); ++m) {
        masks::SourceMask sm;
        sm.rle = masks::rle_encode(sam[m].inside, W, H);
        sm.predicted_iou = sam[m].predicted_iou;
        sm.stability_score = sam[m].stability_score;
        int x0 = W, y0 = H, x1 = -1, y1 = -1;
        for (int y = 0; y < H; ++y)
          for (int x = 0; x < W; ++x)
            if (sam[m].inside[size_t(y) * W + x]) x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x), y1 = std::max(y1, y);
        list.push_back({{"segmentation", {{"size", {H, W}}, {"counts", masks::rle_counts_to_string(sm.rle.counts)}}},
                        {"area", masks::rle_area(sm.rle)},
                        {"bbox", {x0, y0, x1 - x0 + 1, y1 - y0 + 1}},
                        {"predicted_iou", sam[m].predicted_iou},
                        {"point_coords", {{(x0 + x1) / 2, (y0 + y1) / 2}}},
                        {"stability_score", sam[m].stability_score},
                        {"crop_box", {0, 0, W, H}}});
        src.push_back(std::move(sm));
        const int e = sam[m].entity;
        json truth = {{"entity", e}};
        if (e <= K) truth["object"] = e;
        else if (e <= 3 * K) truth["object"] = (e - K - 1) / 2 + 1, truth["part"] = (e - K - 1) % 2 + 1;
        else truth["object"] = 0, truth["surface"] = concept_names[e - 3 * K], surface_used.insert(e - 3 * K);
        ids[std::to_string(pv ? int(m) + 1 : e)] = truth;
      }
      atomic_write_text(dir / "sam" / (stem + ".json"), list.dump() + "\n");
      masks::Flattened f = masks::flatten_masks(src, W, H);  // ids 1 + list position
      if (!pv)
        for (auto& l : f.labels.v)
          if (l) l = uint16_t(sam[l - 1].entity);
      save_label_png(dir / "masks" / (stem + ".png"), f.labels);
      write_npy(dir / "masks" / (stem + ".conf.npy"), make_npy_f32({size_t(H), size_t(W)}, f.confidence.empty() ? std::vector<float>(size_t(W) * H, 1.f).data() : f.confidence.data()));
      ids_out[stem] = ids;
    };
    {
      Progress bar("synth: masks+features", opt.views, opt.progress);
      for (int i = 0; i < opt.views; ++i) {
        const std::string stem = views[i].name.substr(0, views[i].name.size() - 4);
        if (sam_style) {
          write_sam_view(tmp, stem, views[i], K_, world, split, nl, mix(opt.seed, 6, i), per_view, mask_ids);
        } else {
          LabelMap mask;
          std::vector<float> conf;
          simulate_masks(views[i].instances, nl, K, mix(opt.seed, 1, i), mask, conf);
          if (opt.surface_masks)
            for (size_t p = 0; p < mask.v.size(); ++p)
              if (mask.v[p] == 0 && views[i].instances.v[p] == 0 && surface_of[views[i].concept_id[p]])
                mask.v[p] = static_cast<uint16_t>(K + surface_of[views[i].concept_id[p]]);
          if (per_view) {
            mask_ids[stem] = shuffle_ids(mask, mix(opt.seed, 5, i));
            for (auto& [id, truth] : mask_ids[stem].items())  // a surface's id K + j is no object
              if (truth["object"].get<int>() > K)
                truth = {{"object", 0}, {"surface", concept_names[surface_concepts[truth["object"].get<int>() - K - 1]]}};
          }
          save_label_png(tmp / "masks" / (stem + ".png"), mask);
          if (!conf.empty())
            write_npy(tmp / "masks" / (stem + ".conf.npy"), make_npy_f16({size_t(opt.height), size_t(opt.width)}, conf.data()));
        }
        int gh, gw;
        auto feat = simulate_features(views[i], concepts, context, nl.feature, opt.feature_dim, mix(opt.seed, 2, i), gh, gw);
        write_npy(tmp / "features" / (stem + ".npy"), make_npy_f16({size_t(gh), size_t(gw), size_t(opt.feature_dim)}, feat.data()));
        bar.update(i + 1);
      }
      bar.finish();
    }
    if (!per_view) {  // per-view ids name nothing: no objects.json, the truth is in gt/mask_ids.json
      json names = json::object();
      for (auto& o : world.objects) names[std::to_string(o.id)] = o.name;
      if (opt.surface_masks && !sam_style)
        for (size_t j = 0; j < surface_concepts.size(); ++j)
          names[std::to_string(K + 1 + int(j))] = concept_names[surface_concepts[j]];
      if (sam_style) {
        for (auto& o : world.objects)
          if (split[o.id - 1])
            for (int h = 1; h <= 2; ++h) names[std::to_string(K + 2 * (o.id - 1) + h)] = fmt::format("{} (part {})", o.name, h);
        for (size_t c = 1; c < concept_names.size(); ++c)
          if (surface_used.count(int(c))) names[std::to_string(3 * K + int(c))] = concept_names[c];
      }
      atomic_write_text(tmp / "masks" / "objects.json", names.dump(2) + "\n");
    }
    if (per_view || sam_style) atomic_write_text(tmp / "gt" / "mask_ids.json", mask_ids.dump(1) + "\n");
    // Text embeddings: class names (concept + small noise), synonyms (more noise), background surfaces,
    // distractors (pool names not in the scene, plus a few unrelated phrases) and LERF's canonical phrases.
    {
      Rng rng(mix(opt.seed, 3));
      json te = json::object();
      for (auto& o : world.objects) te[o.name] = float_array(noisy(concept_vector(o.name, opt.feature_dim), 0.15, rng));
      for (auto& [syn, name] : world.synonyms) te[syn] = float_array(noisy(concept_vector(name, opt.feature_dim), 0.45, rng));
      for (size_t c = 1; c < concept_names.size(); ++c)
        if (!te.contains(concept_names[c])) te[concept_names[c]] = float_array(noisy(concepts[c], 0.15, rng));
      std::vector<std::string> distract = world.unused_names;
      for (const char* d : {"violin", "sports car", "umbrella", "laptop computer"}) distract.push_back(d);
      for (auto& d : distract) te[d] = float_array(noisy(concept_vector(d, opt.feature_dim), 0.15, rng));
      for (const char* c : {"object", "things", "stuff", "texture"}) {
        auto own = concept_vector(c, opt.feature_dim);
        std::vector<float> v(opt.feature_dim);
        for (int d = 0; d < opt.feature_dim; ++d) v[d] = context[d] + 0.6f * own[d];
        te[c] = float_array(noisy(v, 0.0, rng));
      }
      atomic_write_text(tmp / "text_embeddings.json", te.dump() + "\n");
    }
    // SfM-like points: random visible surface samples with position noise; the track is every view whose
    // depth map agrees with the point's depth there (so occluded views are not in it).
    ColmapModel model;
    model.cameras[1] = ColmapCamera{1, "PINHOLE", uint64_t(opt.width), uint64_t(opt.height), {K_.fx, K_.fy, K_.cx, K_.cy}};
    for (int i = 0; i < opt.views; ++i) {
      ColmapImage im;
      im.id = i + 1;
      im.qvec = rotmat_to_qvec(views[i].R);
      im.tvec = views[i].t;
      im.camera_id = 1;
      im.name = views[i].name;
      model.images.push_back(im);
    }
    {
      Rng rng(mix(opt.seed, 4));
      const double sigma = (opt.preset == "room" ? 0.004 : 0.0015) * (nl.feature > 0 ? 1.0 : 0.5);
      const int W = opt.width, H = opt.height;
      long attempts = 0;
      while (static_cast<int>(model.points.size()) < opt.points && attempts < 20L * opt.points + 1000) {
        ++attempts;
        int v = rng.integer(0, opt.views - 1), x = rng.integer(0, W - 1), y = rng.integer(0, H - 1);
        const RenderedView& rv = views[v];
        float z = rv.depth[size_t(y) * W + x];
        if (z <= 0) continue;
        Vec3 pc((x + 0.5 - K_.cx) / K_.fx * z, (y + 0.5 - K_.cy) / K_.fy * z, z);
        Vec3 X = rv.R.transpose() * (pc - rv.t);
        X += sigma * Vec3(rng.normal(), rng.normal(), rng.normal());
        ColmapPoint p;
        p.id = model.points.size() + 1;
        p.xyz = X;
        for (int c = 0; c < 3; ++c) p.rgb[c] = static_cast<uint8_t>(std::lround(rv.rgb.px[(size_t(y) * W + x) * 3 + c] * 255));
        p.error = rng.uniform(0.3, 1.2);
        std::vector<std::pair<int, Eigen::Vector2d>> obs;
        for (int u = 0; u < opt.views; ++u) {
          Vec3 q = views[u].R * X + views[u].t;
          if (q.z() <= 1e-6) continue;
          double px = K_.fx * q.x() / q.z() + K_.cx, py = K_.fy * q.y() / q.z() + K_.cy;
          if (px < 0 || py < 0 || px >= W || py >= H) continue;
          float dz = views[u].depth[size_t(py) * W + size_t(px)];
          if (dz <= 0 || std::abs(q.z() - dz) > 0.01 * dz + 4 * sigma) continue;
          obs.emplace_back(u, Eigen::Vector2d(px, py));
        }
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
    write_colmap_bin(tmp / "sparse" / "0", model);

    // Labels for the held-out views (every 8th view, the LLFF split hgs uses without test.txt).
    {
      // 3D-OVS classes: the objects and, as the real 3D-OVS labels every surface, the background surfaces
      // (table, floor, walls: every concept that is no object; "sky" = nothing hit stays unlabelled).
      std::vector<std::string> seg_classes;
      for (auto& o : world.objects) seg_classes.push_back(o.name);
      for (int c : surface_concepts) seg_classes.push_back(concept_names[c]);
      std::sort(seg_classes.begin(), seg_classes.end());
      std::string ctext;
      for (auto& c : seg_classes) ctext += c + "\n";
      atomic_write_text(tmp / "segmentations" / "classes.txt", ctext);
      for (int i = 0; i < opt.views; i += 8) {
        const RenderedView& rv = views[i];
        const std::string stem = rv.name.substr(0, rv.name.size() - 4);
        auto save_segmentation = [&](const std::string& cls, const std::vector<uint8_t>& inside) {
          Image seg(opt.width, opt.height, 1);
          for (size_t p = 0; p < inside.size(); ++p) seg.px[p] = inside[p] ? 1.f : 0.f;
          save_png(tmp / "segmentations" / std::to_string(i) / (cls + ".png"), seg);
        };
        for (int c : surface_concepts) {
          std::vector<uint8_t> inside(rv.instances.v.size());
          for (size_t p = 0; p < inside.size(); ++p) inside[p] = rv.concept_id[p] == c && rv.instances.v[p] == 0;
          save_segmentation(concept_names[c], inside);
        }
        json objs = json::array();
        for (auto& o : world.objects) {
          std::vector<uint8_t> inside(rv.instances.v.size());
          size_t cnt = 0;
          for (size_t p = 0; p < inside.size(); ++p) cnt += inside[p] = rv.instances.v[p] == o.id;
          save_segmentation(o.name, inside);
          if (!cnt) continue;
          for (auto& poly : trace_polygons(inside, opt.width, opt.height)) {
            int x1 = opt.width, y1 = opt.height, x2 = 0, y2 = 0;
            json pts = json::array();
            for (auto [x, y] : poly) {
              x1 = std::min(x1, x); y1 = std::min(y1, y); x2 = std::max(x2, x); y2 = std::max(y2, y);
              pts.push_back({x, y});
            }
            objs.push_back({{"category", o.name}, {"bbox", {x1, y1, x2, y2}}, {"segmentation", pts}});
          }
        }
        json label = {{"info", {{"name", rv.name}, {"width", opt.width}, {"height", opt.height}}}, {"objects", objs}};
        atomic_write_text(tmp / "label" / (stem + ".json"), label.dump() + "\n");
      }
    }
    // Record of what was generated.
    {
      json objs = json::array();
      for (auto& o : world.objects)
        objs.push_back({{"id", o.id}, {"name", o.name}, {"shape", o.shape}, {"position", {o.position.x(), o.position.y(), o.position.z()}}});
      json syn = json::object();
      for (auto& [s, n] : world.synonyms) syn[s] = n;
      json meta = {{"generator", "hgs synth " HGS_VERSION},
                   {"preset", opt.preset},
                   {"seed", opt.seed},
                   {"views", opt.views},
                   {"width", opt.width},
                   {"height", opt.height},
                   {"points", opt.points},
                   {"noise", opt.noise},
                   {"noise_params", {{"miss", nl.miss}, {"jitter_px", nl.jitter}, {"merge", nl.merge}, {"swap", nl.swap},
                                     {"confidence_noise", nl.conf_noise}, {"feature_noise", nl.feature}}},
                   {"feature_dim", opt.feature_dim},
                   {"feature_patch", 16},
                   {"objects", objs},
                   {"synonyms", syn},
                   {"distractors", world.unused_names},
                   {"background_concepts", std::vector<std::string>(concept_names.begin() + 1, concept_names.end())}};
      if (per_view) meta["mask_ids"] = opt.mask_ids;  // only when not the default, so default scenes keep their bytes
      if (sam_style) meta["mask_style"] = opt.mask_style;
      if (opt.surface_masks) meta["surface_masks"] = true;
      if (opt.write_depth) meta["depth"] = "gt/depth";
      atomic_write_text(tmp / "synth.json", meta.dump(2) + "\n");
    }
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
