// Import driver: match the tool's files to the scene's views (a file for an image that is not in the COLMAP model
// is an error), read and flatten each view, write label maps, confidences, features and masks/import.json into
// temporary folders, then swap them in.
#include "masks/import.h"

#include <fmt/format.h>

#include <map>
#include <nlohmann/json.hpp>
#include <random>

#include "core/error.h"
#include "core/fs.h"
#include "core/npy.h"
#include "core/progress.h"
#include "masks/sources.h"
#include "scene/colmap.h"
#include "scene/scene.h"

namespace hgs::masks {
namespace fs = std::filesystem;
using json = nlohmann::json;

const std::vector<std::string>& import_formats() {
  static const std::vector<std::string> f = {"sam-json", "sam-png", "sam2-png", "langsplat"};
  return f;
}

int langsplat_level(const std::string& name) {
  if (name == "default") return 0;
  if (name == "s") return 1;
  if (name == "m") return 2;
  if (name == "l") return 3;
  fail("--level: unknown level '{}' (default, s, m or l)", name);
}

namespace {

struct Job {
  int view = -1;
  fs::path file;   // JSON / label PNG / amg folder / LangSplat _s.npy
  fs::path file2;  // LangSplat _f.npy
};

std::string generic_rel(const fs::path& p, const fs::path& root) { return fs::relative(p, root).generic_string(); }

// LangSplat names its files after the image's base name cut at the first '.'.
std::string langsplat_key(const std::string& view_name) {
  std::string base = fs::path(view_name).filename().string();
  return base.substr(0, base.find('.'));
}

std::vector<Job> match_files(const Scene& s, const ImportOptions& opt, const fs::path& model) {
  std::map<std::string, int> by_stem;
  for (auto& v : s.views) by_stem[v.stem] = v.index;
  auto not_in_model = [&](const fs::path& f) {
    fail("{}: masks for an image that is not in the COLMAP model ({})", f.string(), model.string());
  };
  std::vector<Job> jobs;
  if (opt.from == "langsplat") {
    std::map<std::string, int> by_key;
    for (auto& v : s.views) {
      auto [it, fresh] = by_key.emplace(langsplat_key(v.name), v.index);
      if (!fresh)
        fail("{}: images '{}' and '{}' have the same LangSplat file name '{}'", opt.dir.string(),
             s.views[it->second].name, v.name, it->first);
    }
    std::map<int, Job> found;
    for (auto& e : fs::directory_iterator(opt.dir)) {
      const std::string n = e.path().filename().string();
      const bool is_s = n.size() > 6 && n.ends_with("_s.npy"), is_f = n.size() > 6 && n.ends_with("_f.npy");
      if (!is_s && !is_f) continue;
      auto it = by_key.find(n.substr(0, n.size() - 6));
      if (it == by_key.end()) not_in_model(e.path());
      Job& j = found[it->second];
      j.view = it->second;
      (is_s ? j.file : j.file2) = e.path();
    }
    for (auto& [v, j] : found) {
      if (j.file.empty()) fail("{}: no seg map {}_s.npy beside it", j.file2.string(), langsplat_key(s.views[v].name));
      if (j.file2.empty())
        fail("{}: no feature file {}_f.npy beside it", j.file.string(), langsplat_key(s.views[v].name));
      jobs.push_back(j);
    }
    return jobs;
  }
  std::map<int, Job> found;
  for (auto& e : fs::recursive_directory_iterator(opt.dir)) {
    fs::path f = e.path();
    std::string stem;
    if (opt.from == "sam-json" && e.is_regular_file() && f.extension() == ".json") {
      stem = generic_rel(f.parent_path() / f.stem(), opt.dir);
    } else if (opt.from == "sam2-png" && e.is_regular_file() && f.extension() == ".png") {
      stem = generic_rel(f.parent_path() / f.stem(), opt.dir);
    } else if (opt.from == "sam-png" && e.is_regular_file() && f.filename() == "metadata.csv") {
      stem = generic_rel(f.parent_path(), opt.dir);
      f = f.parent_path();
    } else {
      continue;
    }
    auto it = by_stem.find(stem);
    if (it == by_stem.end()) not_in_model(f);
    found[it->second] = Job{it->second, f, {}};
  }
  for (auto& [v, j] : found) jobs.push_back(j);
  return jobs;
}

bool non_empty_dir(const fs::path& d) { return fs::is_directory(d) && !fs::is_empty(d); }

json score_json(double v) { return v >= 0 ? json(v) : json(nullptr); }

// Checks the options; returns the LangSplat level's index.
int check_options(const ImportOptions& opt) {
  const auto& formats = import_formats();
  if (std::find(formats.begin(), formats.end(), opt.from) == formats.end())
    fail("--from: unknown format '{}' (sam-json, sam-png, sam2-png or langsplat)", opt.from);
  if (opt.level_given && opt.from != "langsplat") fail("--level: only LangSplat output has levels (--from langsplat)");
  const int level = langsplat_level(opt.level);
  if (opt.feature_stride < 1 || opt.feature_stride > 256)
    fail("--feature-stride: must be between 1 and 256, got {}", opt.feature_stride);
  if (!fs::is_directory(opt.dir)) fail("{}: mask folder not found", opt.dir.string());
  return level;
}

// Where the imported files go: temporary folders beside masks/ (and features/), swapped in at the end.
struct Output {
  fs::path masks_dir, feat_dir;  // SCENE/masks, SCENE/features
  fs::path tmp_masks, tmp_feat;
  std::string suffix;  // of the temporary and old folders' names
};

// LangSplat, one view: the label map of `level` and the feature grid; returns the view's import.json record.
json import_langsplat_view(const ImportOptions& opt, int level, const Job& j, const View& v, const Output& out,
                           ImportSummary& sum) {
  LangSplatView ls = read_langsplat(j.file, j.file2, level, v.width, v.height, opt.feature_stride);
  save_label_png(out.tmp_masks / (v.stem + ".png"), ls.labels);
  write_npy(out.tmp_feat / (v.stem + ".npy"),
            make_npy_f16({size_t(ls.grid_h), size_t(ls.grid_w), size_t(ls.dim)}, ls.grid.data()));
  sum.masks += ls.num_masks;
  sum.features = true;
  sum.feature_dim = ls.dim, sum.grid_w = ls.grid_w, sum.grid_h = ls.grid_h;
  return {{"file", j.file.string()}, {"num_masks", ls.num_masks}, {"features", j.file2.string()}};
}

// SAM's masks (JSON or amg.py PNG folder), one view: flattened into a label map and its confidence; returns the
// view's import.json record (every mask with its area, visible pixels, part_of and scores).
json import_sam_view(const ImportOptions& opt, const Job& j, const View& v, const Output& out, ImportSummary& sum) {
  std::vector<SourceMask> src = opt.from == "sam-json" ? read_sam_json(j.file, v.width, v.height)
                                                       : read_sam_png_folder(j.file, v.width, v.height);
  Flattened f = flatten_masks(src, v.width, v.height);
  save_label_png(out.tmp_masks / (v.stem + ".png"), f.labels);
  if (!f.confidence.empty()) {
    write_npy(out.tmp_masks / (v.stem + ".conf.npy"),
              make_npy_f32({size_t(v.height), size_t(v.width)}, f.confidence.data()));
    sum.confidence = true;
  }
  const std::vector<int> parent = part_of(src);
  json list = json::array();
  for (size_t i = 0; i < src.size(); ++i) {
    list.push_back({{"id", i + 1},
                    {"source", src[i].source},
                    {"area", rle_area(src[i].rle)},
                    {"visible", f.visible[i]},
                    {"part_of", parent[i] >= 0 ? json(parent[i] + 1) : json(nullptr)},
                    {"predicted_iou", score_json(src[i].predicted_iou)},
                    {"stability_score", score_json(src[i].stability_score)}});
    sum.hidden += f.visible[i] == 0;
  }
  sum.masks += src.size();
  return {{"file", j.file.string()}, {"masks", list}};
}

// masks/import.json: the format, the source folder, what the ids mean, the overlap rule and every view's record.
json import_record(const ImportOptions& opt, const json& views) {
  const bool langsplat = opt.from == "langsplat";
  json meta = {{"format", opt.from},
               {"source", fs::absolute(opt.dir).lexically_normal().string()},
               {"ids", langsplat                ? "index into LangSplat's concatenated mask list + 1 (per view)"
                       : opt.from == "sam2-png" ? "as in the label maps (SAM2's object ids)"
                                                : "1 + position of the mask in the view's list (per view)"},
               {"rule", opt.from == "sam2-png" ? "none (one label per pixel already)"
                        : langsplat            ? "LangSplat's: within a level, later masks overwrite earlier ones"
                                               : "smallest mask wins; equal areas: the mask listed first"},
               {"views", views}};
  if (langsplat) meta["level"] = opt.level, meta["feature_stride"] = opt.feature_stride;
  return meta;
}

// Swap in: the old folder moves aside, the new one into place, the old one is removed.
void swap_in(const fs::path& root, const fs::path& tmp, const fs::path& dst, const std::string& suffix) {
  const fs::path old = root / fmt::format(".{}.old-{}", dst.filename().string(), suffix);
  std::error_code ec;
  if (fs::exists(dst)) {
    fs::rename(dst, old, ec);
    if (ec) fail("{}: cannot move the old folder aside ({})", dst.string(), ec.message());
  }
  fs::rename(tmp, dst, ec);
  if (ec) fail("{}: cannot move the imported folder into place ({})", dst.string(), ec.message());
  fs::remove_all(old, ec);
}

// Imports every job's view into the temporary folders, writes import.json and swaps the folders in.
void write_output(const ImportOptions& opt, int level, const Scene& s, const std::vector<Job>& jobs, const Output& out,
                  ImportSummary& sum) {
  const bool langsplat = opt.from == "langsplat";
  ensure_dir(out.tmp_masks);
  if (langsplat) ensure_dir(out.tmp_feat);
  json views = json::object();
  Progress bar("masks import", long(jobs.size()), opt.progress);
  for (size_t ji = 0; ji < jobs.size(); ++ji) {
    const Job& j = jobs[ji];
    const View& v = s.views[j.view];
    if (langsplat) {
      views[v.stem] = import_langsplat_view(opt, level, j, v, out, sum);
    } else if (opt.from == "sam2-png") {
      save_label_png(out.tmp_masks / (v.stem + ".png"), read_sam2_png(j.file, v.width, v.height));
      views[v.stem] = {{"file", j.file.string()}};
    } else {
      views[v.stem] = import_sam_view(opt, j, v, out, sum);
    }
    ++sum.imported;
    bar.update(long(ji + 1), v.name);
  }
  bar.finish();
  atomic_write_text(out.tmp_masks / "import.json", import_record(opt, views).dump(1) + "\n");
  if (langsplat) swap_in(s.root, out.tmp_feat, out.feat_dir, out.suffix);
  swap_in(s.root, out.tmp_masks, out.masks_dir, out.suffix);
}

}  // namespace

ImportSummary import_masks(const ImportOptions& opt) {
  const int level = check_options(opt);
  Scene s = load_scene(opt.scene);
  const fs::path model = colmap_model_dir(s.root);
  std::vector<Job> jobs = match_files(s, opt, model);
  if (jobs.empty()) fail("{}: no {} files for any image of the scene", opt.dir.string(), opt.from);
  const bool langsplat = opt.from == "langsplat";
  Output out;
  out.masks_dir = s.root / "masks", out.feat_dir = s.root / "features";
  if (!opt.force && non_empty_dir(out.masks_dir))
    fail("{}: already holds masks; pass --force to replace them", out.masks_dir.string());
  if (!opt.force && langsplat && non_empty_dir(out.feat_dir))
    fail("{}: already holds features; pass --force to replace them", out.feat_dir.string());

  ImportSummary sum;
  sum.views = int(s.views.size());
  std::vector<char> has(s.views.size(), 0);
  for (auto& j : jobs) has[j.view] = 1;
  for (auto& v : s.views)
    if (!has[v.index]) sum.missing.push_back(v.name);

  out.suffix = fmt::format("{:08x}", std::random_device{}());
  out.tmp_masks = s.root / fmt::format(".masks.import-{}", out.suffix);
  out.tmp_feat = s.root / fmt::format(".features.import-{}", out.suffix);
  try {
    write_output(opt, level, s, jobs, out, sum);
  } catch (...) {
    std::error_code ec;
    fs::remove_all(out.tmp_masks, ec);
    fs::remove_all(out.tmp_feat, ec);
    throw;
  }
  return sum;
}

}  // namespace hgs::masks
