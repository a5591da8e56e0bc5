// The `hgs prepare` driver: runs the stages of prepare.h in order, skipping complete ones (stages.h).
#include "prepare/prepare.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <set>

#include "clip/scene_features.h"
#include "core/error.h"
#include "core/fs.h"
#include "masks/import.h"
#include "prepare/input_dir.h"
#include "prepare/run_tool.h"
#include "prepare/scene_lock.h"
#include "prepare/sparse_retry.h"
#include "prepare/stage_info.h"
#include "prepare/stage_options.h"
#include "prepare/stages.h"
#include "sam/scene_masks.h"
#include "scene/scene.h"
#include "scene/text_embeddings.h"
#include "train/depth_model.h"

namespace hgs::prepare {
namespace fs = std::filesystem;

const std::vector<std::pair<std::string, std::string>>& stage_groups() {
  static const std::vector<std::pair<std::string, std::string>> g = {
      {"input", "input"},         {"features", "poses"},       {"matching", "poses"},  {"mapping", "poses"},
      {"retry_mapping", "poses"}, {"retry_features", "poses"}, {"undistort", "poses"}, {"sam", "masks"},
      {"import", "masks"},        {"depth", "masks"},          {"associate", "masks"}, {"clip", "language"},
      {"text", "language"}};
  return g;
}

namespace {

// Runs stages in order with their keys, timing them and skipping those the log records complete.
class Pipeline {
 public:
  Pipeline(const PrepareOptions& opt) : opt_(opt), log_(opt.scene / "prepare" / "state.json") {}

  // The stage keys: the input's (a hash of what it produced), then every other stage's (stage_options.h).
  void set_input_key(const std::string& key) { keys_["input"] = key; }
  void set_options(const StageOptions& o) { keys_ = stage_keys(o, keys_.at("input")); }

  // Runs `fn` as stage `name` unless complete with its key, so that a change reruns exactly the stages
  // downstream of it. Returns false when --until stopped the run before this stage. `before`: seconds of work
  // done for it before the call (the input stage computes its key so).
  bool stage(const std::string& name, const std::function<nlohmann::json()>& fn, double before = 0) {
    if (stopped_) return false;
    const std::string key = keys_.at(name);
    StageRun r{name, 0, log_.done(name, key)};
    if (r.reused) {
      r.seconds = log_.seconds(name);
    } else {
      resuming_ = log_.started(name, key);
      log_.start(name, key);
      const auto t0 = std::chrono::steady_clock::now();
      nlohmann::json info = fn();
      r.seconds = before + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      log_.finish(name, key, r.seconds, info);
    }
    runs_.push_back(r);
    if (!opt_.until.empty() && (opt_.until == name || (opt_.until == group(name) && last_of_group(name))))
      stopped_ = true;
    return true;
  }
  // Inside a stage: an earlier run started it with the same key (its per-view outputs may be kept).
  bool resuming() const { return resuming_; }
  // What stage `name` recorded when it completed (stage_info.h); has_info: whether it did.
  template <class Info>
  Info info(const std::string& name) const {
    return log_.info(name).get<Info>();
  }
  bool has_info(const std::string& name) const { return !log_.info(name).empty(); }
  const std::vector<StageRun>& runs() const { return runs_; }
  bool stopped() const { return stopped_; }

 private:
  static std::string group(const std::string& name) {
    for (auto& [s, g] : stage_groups())
      if (s == name) return g;
    return "";
  }
  static bool last_of_group(const std::string& name) {
    const auto& g = stage_groups();
    for (size_t i = 0; i < g.size(); ++i)
      if (g[i].first == name) return i + 1 == g.size() || g[i + 1].second != g[i].second;
    return false;
  }
  const PrepareOptions& opt_;
  StageLog log_;
  std::map<std::string, std::string> keys_;  // stage -> key
  std::vector<StageRun> runs_;
  bool stopped_ = false, resuming_ = false;
};

// A path the run will read or write, checked before anything else so that a name longer than the file system
// allows or a folder on the way that cannot be searched is one line naming the path, not an internal error.
// Returns whether it exists.
bool check_path(const fs::path& p, const char* what) {
  for (const fs::path& part : p)
    if (part.native().size() > 255)
      fail("{}: a name in the {} path is {} bytes long; file systems allow at most 255", p.string(), what,
           part.native().size());
  std::error_code ec;
  const fs::file_status st = fs::status(p, ec);
  if (ec && ec != std::errc::no_such_file_or_directory)
    fail("{}: cannot reach the {} ({})", p.string(), what, ec.message());
  return fs::exists(st);
}

// SCENE may be new, empty, or one hgs prepare made; anything else is left alone.
void check_scene_folder(const fs::path& scene, const fs::path& input) {
  std::error_code ec;
  if (!check_path(scene, "--out")) return;
  if (!fs::is_directory(scene, ec)) fail("{}: --out exists and is not a folder", scene.string());
  const bool ours = fs::exists(scene / "prepare" / "state.json", ec) || fs::exists(scene / "prepare" / "lock", ec);
  if (!fs::is_empty(scene, ec) && !ours)
    fail("{}: --out is a folder hgs prepare did not make (no prepare/state.json): give a new or empty folder",
         scene.string());
  if (ec) fail("{}: cannot read the --out folder ({})", scene.string(), ec.message());
  if (fs::equivalent(scene, input, ec)) fail("{}: --out must not be the input folder", scene.string());
}

InputInfo input_info(const InputReport& r, const fs::path& input, bool video) {
  InputInfo in;
  in.path = resolved_path(input).string(), in.kind = video ? "video" : "photos", in.images = int(r.images.size());
  in.not_images = r.not_images, in.bad = r.bad, in.blurred = r.blurred, in.broken_links = r.broken_links;
  for (const auto& [from, to] : r.renamed) in.renamed.push_back({from, to});
  for (const InputImage& im : r.images) {
    in.resized += im.resized;
    in.rotated += im.orientation != 1;
    in.list.push_back({im.name, im.width, im.height, im.orientation, im.source});
  }
  return in;
}

std::vector<std::string> input_names(const InputInfo& in) {
  std::vector<std::string> names;
  for (const InputEntry& e : in.list) names.push_back(e.name);
  return names;
}

}  // namespace

// ---- stages -------------------------------------------------------------------------------------------------

namespace {

void input_stage(Pipeline& p, const PrepareOptions& opt, const fs::path& work) {
  // The input stage always runs (it keeps outputs whose source is unchanged): its key is what it produced.
  const auto t0 = std::chrono::steady_clock::now();
  const bool video = is_video_input(opt.input);
  if (!video && !fs::is_directory(opt.input)) fail("{}: not a folder of photos or a video file", opt.input.string());
  InputReport r =
      video ? import_video(opt.input, work / "input", opt.in) : import_photos(opt.input, work / "input", opt.in);
  const nlohmann::json info = input_info(r, opt.input, video);
  if (r.images.size() < 3)
    fail(
        "{}: {} image{} found{}: COLMAP needs at least 3 overlapping views (20-200 photos around the subject work "
        "best)",
        opt.input.string(), r.images.size(), r.images.size() == 1 ? "" : "s",
        r.not_images.empty() ? "" : fmt::format(" ({} other files skipped)", r.not_images.size()));
  // The key: what the stage produced (the resolved source paths, names, sizes) and the bytes of every output, so
  // that the folder typed another way keeps every later stage, and a photo replaced by another of the same size
  // reruns them.
  std::string content;
  for (const InputImage& im : r.images) content += "|" + im.name + ":" + hash_file_content(work / "input" / im.name);
  p.set_input_key(hash_key("input|" + info.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + content));
  p.stage(
      "input", [&] { return info; }, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
}

// Every stage's options from the command's, once the input is known (the matcher depends on it).
StageOptions stage_options(const PrepareOptions& opt, int n_images, bool video) {
  StageOptions o;
  o.features = {opt.pose.camera_model, opt.pose.max_features};
  PoseOptions po = opt.pose;
  po.ordered = video;
  o.matching = {choose_matcher(po, n_images), opt.pose.vocab_tree};
  o.sam = {opt.sam_key, opt.amg};
  o.depth.iters = opt.depth_iters;
  o.associate.associate = opt.associate;
  o.clip = {opt.clip_key, opt.dense};
  o.text.model = opt.clip_key;
  o.text.phrases = opt.phrases;
  for (const char* c : kCanonicalPhrases)
    if (std::find(o.text.phrases.begin(), o.text.phrases.end(), c) == o.text.phrases.end()) o.text.phrases.push_back(c);
  return o;
}

void pose_stages(Pipeline& p, const PrepareOptions& opt, const StageOptions& so, const fs::path& work) {
  fs::path exe;  // found when a stage needs it: a scene whose poses are complete does not need colmap
  auto colmap = [&] {
    if (exe.empty()) exe = require_tool({opt.pose.colmap, "colmap"}, "--colmap");
    return exe;
  };
  const std::vector<std::string> names = input_names(p.info<InputInfo>("input"));
  const int n = int(names.size());
  // The COLMAP settings of the stages: their options, the program and the progress bars.
  PoseOptions po;
  po.colmap = opt.pose.colmap, po.progress = opt.pose.progress;
  po.camera_model = so.features.camera_model, po.max_features = so.features.max_features;
  po.matcher = so.matching.matcher, po.vocab_tree = so.matching.vocab_tree;
  const std::string matcher = so.matching.matcher;
  p.stage("features", [&] {
    fs::remove(work / "database.db");
    extract_features(colmap(), work / "input", work, po);
    return nlohmann::json::object();
  });
  p.stage("matching", [&] {
    match_features(colmap(), work, matcher, n, po);
    return nlohmann::json(MatchingInfo{matcher});
  });
  p.stage("mapping", [&] {
    return nlohmann::json(map_and_summarize(colmap(), work / "input", work, names, po, "sparse", opt.scene, "default"));
  });
  // A sparse capture: COLMAP's wide-baseline settings, the mapper first (cheap), then everything (poses.h).
  PoseOptions wide = po;
  wide.wide_baseline = true;
  auto announce = [&](const MappingInfo& m, const std::string& next) {
    if (opt.progress)
      fmt::print(stderr, "colmap registered only {} of {} images{}: retrying with {}\n", m.registered, m.images,
                 m.retried.empty() ? "" : " so far", next);
  };
  p.stage("retry_mapping", [&] {
    const MappingInfo m = p.info<MappingInfo>("mapping");
    if (registered_enough(m)) return nlohmann::json(m);
    announce(m, "COLMAP's wide-baseline mapper options");
    return nlohmann::json(keep_better(m, map_and_summarize(colmap(), work / "input", work, names, wide, "sparse_wide",
                                                           opt.scene, "wide-baseline mapper")));
  });
  p.stage("retry_features", [&] {
    const MappingInfo m = p.info<MappingInfo>("retry_mapping");
    if (registered_enough(m)) return nlohmann::json(m);
    announce(m, fmt::format("wide-baseline features ({}, affine, domain-size pooling) and guided matching",
                            wide_features(po.max_features)));
    const fs::path dir = work / "retry";
    fs::remove_all(dir);
    ensure_dir(dir);
    extract_features(colmap(), work / "input", dir, wide);
    match_features(colmap(), dir, matcher, n, wide);
    return nlohmann::json(keep_better(m, map_and_summarize(colmap(), work / "input", dir, names, wide, "sparse",
                                                           opt.scene, "wide-baseline features")));
  });
  if (p.stopped()) return;
  const MappingInfo m = p.info<MappingInfo>("retry_features");
  check_registration(m, opt.allow_partial);
  p.stage("undistort", [&] {
    undistort(colmap(), work / "input", model_folder(m, opt.scene), work, opt.scene, po);
    return nlohmann::json::object();
  });
}

void mask_stages(Pipeline& p, const PrepareOptions& opt, const StageOptions& so, const fs::path& work) {
  const fs::path sam_dir = work / "sam";
  p.stage("sam", [&] {
    // A run started with the same key keeps the views it wrote; another key starts over.
    if (!p.resuming()) fs::remove_all(sam_dir);
    Scene s = load_scene(opt.scene);
    sam::SamModel m = opt.load_sam();
    sam::SceneMasksSummary r = sam::write_sam_files(s, m, so.sam.amg, sam_dir, false, opt.progress);
    return nlohmann::json(SamInfo{int(s.views.size()), r.written});
  });
  p.stage("import", [&] {
    fs::remove_all(opt.scene / "masks");
    masks::ImportOptions io;
    io.scene = opt.scene, io.from = "sam-json", io.dir = sam_dir, io.force = true, io.progress = opt.progress;
    masks::ImportSummary r = masks::import_masks(io);
    return nlohmann::json(ImportInfo{r.imported, r.masks, r.hidden});
  });
  const fs::path depth_model = work / "depth_model";  // a model folder (train/run.h)
  const int depth_iters = so.depth.iters;
  p.stage("depth", [&] {
    if (depth_iters > 0) train::train_depth_model(load_scene(opt.scene), depth_iters, depth_model, opt.progress);
    return nlohmann::json(DepthInfo{depth_iters});
  });
  p.stage("associate", [&] {
    masks::AssociateOptions a = so.associate.associate;
    a.scene = opt.scene, a.out_masks.clear(), a.names.clear(), a.force = true, a.progress = opt.progress;
    if (depth_iters > 0) a.depth = train::depth_from_model(depth_model);
    masks::AssociateSummary r = masks::associate_masks(a);
    return nlohmann::json(AssociateInfo{int(r.objects.size()), r.masks, r.views_with_masks});
  });
}

void language_stages(Pipeline& p, const PrepareOptions& opt, const StageOptions& so) {
  p.stage("clip", [&] {
    if (!p.resuming()) fs::remove_all(opt.scene / "features");
    Scene s = load_scene(opt.scene);
    clip::ClipModel m = opt.load_clip();
    clip::SceneFeaturesSummary r = clip::write_clip_features(s, m, so.clip.dense, false, opt.progress);
    return nlohmann::json(ClipInfo{int(s.views.size()), {r.grid_w, r.grid_h}, m.embed_dim});
  });
  const std::vector<std::string>& phrases = so.text.phrases;
  p.stage("text", [&] {
    clip::ClipModel m = opt.load_clip();
    if (!m.has_text) fail("{}: the CLIP model has no text tower (text_embeddings.json needs one)", opt.clip_key);
    std::vector<float> e = m.embed_text(phrases);
    nlohmann::json out = nlohmann::json::object();
    add_text_embeddings(out, phrases, e, m.embed_dim);
    write_text_embeddings(opt.scene / "text_embeddings.json", out);
    return nlohmann::json(TextInfo{phrases});
  });
}

// Masks per view from the SAM files (mean, min, max), or an empty object.
nlohmann::json masks_per_view(const fs::path& sam_dir) {
  std::vector<size_t> n;
  if (fs::is_directory(sam_dir))
    for (const auto& e : fs::directory_iterator(sam_dir))
      if (e.path().extension() == ".json") {
        try {
          n.push_back(nlohmann::json::parse(read_file_text(e.path())).size());
        } catch (const nlohmann::json::exception&) {
        }
      }
  if (n.empty()) return nlohmann::json::object();
  size_t sum = 0;
  for (size_t k : n) sum += k;
  return {{"views", n.size()},
          {"mean", double(sum) / double(n.size())},
          {"min", *std::min_element(n.begin(), n.end())},
          {"max", *std::max_element(n.begin(), n.end())}};
}

nlohmann::json prepare_json(const Pipeline& p, const PrepareOptions& opt) {
  nlohmann::json j;
  j["scene"] = opt.scene.string();
  j["input"] = p.info<InputInfo>("input");
  j["input"].erase("list");
  j["poses"] = nlohmann::json::object();
  for (const char* stage : {"mapping", "retry_features"})  // the retries' record when they ran
    if (p.has_info(stage)) {
      j["poses"] = p.info<MappingInfo>(stage);
      j["poses"].erase("model_path");
      j["poses"].erase("model");
    }
  j["masks"] = nlohmann::json::object();
  if (opt.load_sam && p.has_info("associate")) {
    j["masks"] = p.info<AssociateInfo>("associate");
    j["masks"]["masks_per_view"] = masks_per_view(opt.scene / "prepare" / "sam");
    j["masks"]["depth_iters"] = p.info<DepthInfo>("depth").iters;
  }
  j["language"] = nlohmann::json::object();
  if (opt.load_clip && p.has_info("clip")) {
    j["language"] = p.info<ClipInfo>("clip");
    j["language"]["phrases"] = p.info<TextInfo>("text").phrases;
  }
  nlohmann::json st = nlohmann::json::array();
  double total = 0;
  for (const StageRun& r : p.runs()) {
    st.push_back({{"stage", r.name}, {"seconds", r.seconds}, {"reused", r.reused}});
    if (!r.reused) total += r.seconds;
  }
  j["stages"] = st;
  j["total_seconds"] = total;
  if (!opt.until.empty()) j["until"] = opt.until;
  return j;
}

}  // namespace

PrepareReport run_prepare(const PrepareOptions& opt) {
  if (!check_path(opt.input, "INPUT")) fail("{}: no such folder or video file", opt.input.string());
  check_scene_folder(opt.scene, opt.input);
  const fs::path work = opt.scene / "prepare";
  ensure_dir(work);
  const SceneLock lock(work);
  Pipeline p(opt);
  input_stage(p, opt, work);
  const InputInfo in = p.info<InputInfo>("input");
  const StageOptions so = stage_options(opt, in.images, in.kind == "video");
  p.set_options(so);
  if (!p.stopped()) pose_stages(p, opt, so, work);
  if (!p.stopped() && opt.load_sam) mask_stages(p, opt, so, work);
  if (!p.stopped() && opt.load_clip) language_stages(p, opt, so);
  PrepareReport r;
  r.stages = p.runs();
  r.json = prepare_json(p, opt);
  atomic_write_text(opt.scene / "prepare.json",
                    r.json.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
  return r;
}

}  // namespace hgs::prepare
