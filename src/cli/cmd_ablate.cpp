// `hgs ablate SCENE... --out DIR`: the paper's Table 3. Trains the rows (Observation Fusion, Semantic Contrastive
// Learning and Boundary Reconstruction Optimization each on or off; optionally the full method with eq. 15 alone,
// --lambda-rgb 0) on every scene and seed, evaluates each model on the held-out views with the chosen protocols
// and modes (query/evaluate.h), and writes mean and standard deviation per row over the (scene, seed) runs, and the
// paired differences of mIoU (each row minus all-off, each component added to the other two) with 95 % intervals
// clustered by scene (eval/paired_stats.h: seeds averaged within a scene, n = scenes). Pixel mode with hgs's
// default rule (the object-embedding map, not in the paper) also reports the paper's language map under
// "<protocol>/pixel-paper-map" (query/evaluate.h).
//
// Layout: DIR/<scene folder name>/seed<S>/<row>/ is a model folder (train/run.h: point_cloud.ply, config.json,
// train_stats.json) with report.json, report.md and run.json, then
// DIR/ablation.json (every run and the per-row summaries) and DIR/ablation.md (one table per protocol and mode),
// both rewritten after every run so a long ablation shows its progress. A run whose run.json exists (same
// iterations, protocols and modes) is reused, so an interrupted ablation continues where it stopped;
// --reevaluate evaluates such runs' kept models again instead (after a change in the evaluation).
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>

#include "cli/command.h"
#include "core/error.h"
#include "core/fs.h"
#include "eval/paired_stats.h"
#include "eval/report.h"
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "query/evaluate.h"
#include "query/session.h"
#include "train/registry.h"
#include "train/run.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

struct AblateArgs {
  std::vector<std::string> scenes;
  std::string out, rows = "all", protocol = "auto", mode = "object", relevancy = "objects", scl_background = "auto";
  int iters = 3000, downscale = 1, threads = 0, seeds = 1, objects_per_step = 0;
  float anchor_support = 0.f;  // object mode: query::QueryOptions::anchor_support (0 = off)
  uint64_t seed = 0;
  bool eq15_row = false, reevaluate = false, quiet = false, no_paper_map = false;
};

struct Row {
  std::string name;
  bool of, scl, bro;
  float lambda_rgb;
};

std::vector<Row> make_rows(const AblateArgs& a) {
  if (a.rows != "all" && a.rows != "ends" && a.rows != "middle" && a.rows != "full" && a.rows != "leave-one-out" &&
      a.rows != "single")
    fail("--rows: all, ends, middle, full, leave-one-out or single");
  const float lambda_rgb = hybrid::HybridConfig{}.lambda_rgb;
  std::vector<Row> rows;
  for (int r = 0; r < 8; ++r) {
    const bool end = r == 0 || r == 7, one_short = r == 3 || r == 5 || r == 6;  // the full method less one
    const bool alone = r == 1 || r == 2 || r == 4;                              // one component on
    if ((a.rows == "ends" && !end) || (a.rows == "middle" && end) || (a.rows == "full" && r != 7) ||
        (a.rows == "leave-one-out" && !end && !one_short) || (a.rows == "single" && !alone))
      continue;
    const bool of = r & 1, scl = r & 2, bro = r & 4;
    rows.push_back({fmt::format("of{}_scl{}_bro{}", int(of), int(scl), int(bro)), of, scl, bro, lambda_rgb});
  }
  if (a.eq15_row) rows.push_back({"of1_scl1_bro1_eq15", true, true, true, 0.f});
  return rows;
}

// The protocols to run: a comma-separated list, or "auto" (instances where gt/instances/ exists, else lerf-ovs).
std::vector<std::string> protocols_for(const std::string& spec, const std::vector<Scene>& scenes) {
  std::vector<std::string> out;
  if (spec == "auto") {
    out.push_back(query::has_protocol_labels(scenes[0], "instances") ? "instances" : "lerf-ovs");
  } else {
    size_t b = 0;
    while (b <= spec.size()) {
      size_t e = spec.find(',', b);
      if (e == std::string::npos) e = spec.size();
      const std::string p = spec.substr(b, e - b);
      query::parse_protocol(p);  // fails with the list of protocols
      out.push_back(p);
      b = e + 1;
    }
  }
  for (const Scene& s : scenes)
    for (const auto& p : out)
      if (!query::has_protocol_labels(s, p)) fail("{}: no labels for the {} protocol", s.root.string(), p);
  return out;
}

using eval::mean_std;

std::string pct(double v) { return std::isfinite(v) ? fmt::format("{:.2f}", 100 * v) : "-"; }
std::string pct_pm(const std::pair<double, double>& ms) {
  if (!std::isfinite(ms.first)) return "-";
  return std::isfinite(ms.second) ? fmt::format("{:.2f} ± {:.2f}", 100 * ms.first, 100 * ms.second) : pct(ms.first);
}

// Evaluates the model dir/point_cloud.ply with the protocols and modes asked, writes dir/report.json and .md,
// sets run["results"] {"<protocol>/<mode>": {"acc", "miou", "mbiou", "records"}} (mode object, pixel or
// pixel-paper-map) and writes dir/run.json.
void evaluate_run(const AblateArgs& a, const std::string& scene_path, const std::vector<std::string>& protocols,
                  const fs::path& dir, json& run) {
  query::Session s(scene_path, dir / "point_cloud.ply", a.downscale, "");
  std::vector<eval::EvalReport> reports;
  for (const auto& p : protocols) {
    query::EvaluateOptions eo;
    eo.protocol = p;
    eo.object = a.mode != "pixel";
    eo.pixel = a.mode != "object";
    eo.relevancy = query::parse_relevancy(a.relevancy);
    eo.paper_map = !a.no_paper_map;
    eo.object_query.anchor_support = a.anchor_support;
    eo.progress = false;
    for (auto& r : query::evaluate_model(s, eo)) reports.push_back(std::move(r));
  }
  eval::write_reports(dir / "report.json", dir / "report.md", reports);
  if (a.anchor_support > 0) run["anchor_support"] = a.anchor_support;
  else run.erase("anchor_support");
  run["results"] = json::object();
  for (const auto& r : reports) {
    const eval::MeanRow m = eval::scene_mean(r);
    auto num = [](double v) { return std::isfinite(v) ? json(v) : json(nullptr); };
    run["results"][r.protocol + "/" + r.mode] = {{"acc", num(eval::paper_accuracy(m, r.protocol))},
                                                 {"miou", num(m.miou)},
                                                 {"mbiou", num(m.mbiou)},
                                                 {"records", m.count}};
  }
  atomic_write_text(dir / "run.json", run.dump(2) + "\n");
}

// One trained and evaluated row: {"<protocol>/<mode>": {"acc", "miou", "mbiou", "records"}, "train_seconds"}.
json train_and_evaluate(const AblateArgs& a, const Scene& scene, const std::string& scene_path, const Row& row,
                        uint64_t seed, const std::vector<std::string>& protocols, const fs::path& dir,
                        const std::string& label) {
  hybrid::HybridConfig hc;
  hc.use_of = row.of;
  hc.use_scl = row.scl;
  hc.use_bro = row.bro;
  hc.lambda_rgb = row.lambda_rgb;
  hc.scl_background = a.scl_background;
  hc.objects_per_step = a.objects_per_step;
  train::TrainConfig cfg = train::TrainConfig{}.scaled_to(a.iters);
  cfg.method = "hybrid";
  cfg.seed = seed;
  const auto t0 = std::chrono::steady_clock::now();
  hybrid::register_method();
  auto trainer = train::make_trainer(scene, scene.train_indices(), cfg, "hybrid", hc.to_json(), false);
  train::RunOptions ro;
  ro.out = dir;
  ro.progress = !a.quiet;
  ro.label = label;
  train::TrainingRun training(*trainer, scene, ro,
                              train::run_config(*trainer, scene, hc.to_json(), trainer->model().n));
  training.train();
  training.save();
  const double train_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  trainer.reset();
  json run = {{"train_seconds", train_s},
              {"iters", a.iters},
              {"seed", seed},
              {"objects_per_step", a.objects_per_step},
              {"results", json::object()}};
  evaluate_run(a, scene_path, protocols, dir, run);
  return run;
}

// The scenes of the command line; two with the same folder name would share DIR/<name>/.
std::vector<Scene> load_scenes(const AblateArgs& a) {
  std::vector<Scene> scenes;
  std::set<std::string> names;
  for (const auto& p : a.scenes) {
    scenes.push_back(load_scene(p, {a.downscale, false}));
    if (!names.insert(fs::absolute(p).lexically_normal().filename().string()).second)
      fail("{}: two scenes share the folder name '{}' (their runs would share DIR/<name>/)", p,
           fs::absolute(p).lexically_normal().filename().string());
  }
  return scenes;
}

// The results gathered so far, over the (scene, seed) runs in run order.
struct Tally {
  std::vector<std::map<std::string, std::map<std::string, std::vector<double>>>> acc;  // [row] key -> metric -> v
  std::vector<std::string> keys;  // "<protocol>/<mode>" in first-seen order
  json runs = json::array();      // {"scene", "seed", "row", "dir", "run"}
};

// What a results key's pixel figures score, for its table's heading ("" for object mode).
std::string pixel_rule(const std::string& key, const std::string& relevancy) {
  if (key.ends_with("/pixel-paper-map"))
    return " (the paper's language map, eq. 8 summed over objects, scored with LERF's relevancy: `--relevancy lerf`)";
  if (!key.ends_with("/pixel")) return "";
  const char* what = relevancy == "objects"        ? "hgs's object-embedding map, not in the paper"
                     : relevancy == "objects-lerf" ? "LERF's relevancy of hgs's object-embedding map, not in the paper"
                     : relevancy == "lerf"         ? "the paper's language map with LERF's relevancy"
                                           : "the paper's map's relevancy times the foreground, not in the paper";
  return fmt::format(" (relevancy {}: {})", relevancy, what);
}

// One table per protocol and mode: mean ± sample std of each row's mAcc, mIoU, mBIoU.
std::string row_tables(const AblateArgs& a, const std::vector<Row>& rows, const Tally& t) {
  std::string md;
  for (const auto& key : t.keys) {
    md += fmt::format(
        "\n## {}{}\n\n| OF | SCL | BRO | λ_rgb | mAcc | mIoU | mBIoU | runs |\n|---|---|---|---|---|---|---|---|\n",
        key, pixel_rule(key, a.relevancy));
    for (size_t r = 0; r < rows.size(); ++r) {
      auto it = t.acc[r].find(key);
      if (it == t.acc[r].end()) continue;
      const auto& v = it->second;
      md += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} |\n", rows[r].of ? "x" : "-", rows[r].scl ? "x" : "-",
                        rows[r].bro ? "x" : "-", rows[r].lambda_rgb, pct_pm(mean_std(v.at("acc"))),
                        pct_pm(mean_std(v.at("miou"))), pct_pm(mean_std(v.at("mbiou"))), v.at("miou").size());
    }
  }
  return md;
}

// Paired differences of mIoU over the (scene, seed) runs both rows have: every row minus all-off, and each
// component added to the other two (the full row minus the full row without it), with 95 % intervals clustered
// by scene (eval::paired_by_scene). Returns the JSON and Markdown.
std::pair<json, std::string> paired_tables(const std::vector<Row>& rows, const Tally& t) {
  // (scene, seed) -> row -> results
  std::map<std::pair<std::string, uint64_t>, std::map<std::string, const json*>> by_run;
  for (const auto& run : t.runs)
    by_run[{run["scene"].get<std::string>(), run["seed"].get<uint64_t>()}][run["row"].get<std::string>()] =
        &run["run"]["results"];
  auto diffs = [&](const std::string& key, const std::string& a_row, const std::string& b_row) {
    std::vector<std::pair<std::string, double>> d;  // {scene, a - b} per run
    for (const auto& [id, rs] : by_run) {
      auto ia = rs.find(a_row), ib = rs.find(b_row);
      if (ia == rs.end() || ib == rs.end() || !ia->second->contains(key) || !ib->second->contains(key)) continue;
      const json &va = (*ia->second)[key]["miou"], &vb = (*ib->second)[key]["miou"];
      if (va.is_number() && vb.is_number()) d.push_back({id.first, va.get<double>() - vb.get<double>()});
    }
    return eval::paired_by_scene(d);
  };
  json paired_json = json::object();
  std::string pmd;
  for (const auto& key : t.keys) {
    std::vector<std::pair<std::string, eval::ScenePaired>> lines;
    for (const Row& row : rows)
      if (row.name != "of0_scl0_bro0")
        lines.push_back({row.name + " - all off", diffs(key, row.name, "of0_scl0_bro0")});
    for (const char* c : {"of", "scl", "bro"}) {
      std::string without = "of1_scl1_bro1";
      without.replace(without.find(c) + std::string(c).size(), 1, "0");
      lines.push_back({fmt::format("{} added to the other two", c), diffs(key, "of1_scl1_bro1", without)});
    }
    std::string body;
    for (const auto& [what, p] : lines) {
      if (p.runs == 0) continue;
      paired_json[key][what] = {{"mean", std::isfinite(p.mean) ? json(p.mean) : json(nullptr)},
                                {"ci95_half", std::isfinite(p.half) ? json(p.half) : json(nullptr)},
                                {"scenes", p.scenes},
                                {"runs", p.runs}};
      body += fmt::format("| {} | {} | {} | {} | {} |\n", what, pct(p.mean),
                          std::isfinite(p.half) ? fmt::format("± {:.2f}", 100 * p.half) : "-", p.scenes, p.runs);
    }
    if (!body.empty())
      pmd += fmt::format(
          "\n### {} (mIoU, paired by scene, seeds averaged within a scene; n = scenes)\n\n"
          "| difference | mean | 95 % interval | scenes | runs |\n|---|---|---|---|---|\n{}",
          key, body);
  }
  return {paired_json, pmd.empty() ? pmd
                                   : "\n## Paired differences\n\nEach difference is averaged over a scene's seeds "
                                     "first; the mean is over the scenes and the 95 % interval is Student's t over "
                                     "them (n - 1 degrees of freedom; none with one scene).\n" +
                                         pmd};
}

// Per row and key: the runs and the mean and std of each metric.
json row_summaries(const std::vector<Row>& rows, const Tally& t) {
  json summary = json::array();
  for (size_t r = 0; r < rows.size(); ++r) {
    json res = json::object();
    for (const auto& [key, v] : t.acc[r]) {
      json k = {{"runs", v.at("miou").size()}};
      for (const char* m : {"acc", "miou", "mbiou"}) {
        auto [mean, sd] = mean_std(v.at(m));
        k[std::string(m) + "_mean"] = std::isfinite(mean) ? json(mean) : json(nullptr);
        k[std::string(m) + "_std"] = std::isfinite(sd) ? json(sd) : json(nullptr);
      }
      res[key] = k;
    }
    summary.push_back({{"row", rows[r].name},
                       {"of", rows[r].of},
                       {"scl", rows[r].scl},
                       {"bro", rows[r].bro},
                       {"lambda_rgb", rows[r].lambda_rgb},
                       {"results", res}});
  }
  return summary;
}

// DIR/ablation.json and DIR/ablation.md from the runs so far; returns the Markdown.
std::string write_summary(const AblateArgs& a, size_t num_scenes, const std::vector<std::string>& protocols,
                          const std::vector<Row>& rows, const Tally& t) {
  std::string md = fmt::format(
      "# Ablation ({} iterations; {} scene(s) x {} seed(s); mean ± sample std over the runs)\n\nScenes: {}\n", a.iters,
      num_scenes, a.seeds, fmt::join(a.scenes, ", "));
  md += row_tables(a, rows, t);
  auto [paired_json, paired_md] = paired_tables(rows, t);
  md += paired_md;
  std::vector<std::string> abs_scenes;
  for (const auto& p : a.scenes) abs_scenes.push_back(fs::absolute(p).lexically_normal().string());
  const json j = {{"scenes", abs_scenes},
                  {"seeds", a.seeds},
                  {"first_seed", a.seed},
                  {"iters", a.iters},
                  {"protocols", protocols},
                  {"mode", a.mode},
                  {"relevancy", a.relevancy},
                  {"paper_map", !a.no_paper_map},
                  {"scl_background", a.scl_background},
                  {"objects_per_step", a.objects_per_step},
                  {"anchor_support", a.anchor_support},
                  {"summary", row_summaries(rows, t)},
                  {"paired", paired_json},
                  {"runs", t.runs}};
  atomic_write_text(fs::path(a.out) / "ablation.json", j.dump(2) + "\n");
  atomic_write_text(fs::path(a.out) / "ablation.md", md);
  return md;
}

// The run.json of an earlier, interrupted ablation in `dir`, when it ran what is asked now (same iterations and
// objects per step, every protocol and mode); with --reevaluate its kept model is evaluated again (`again`).
std::optional<json> reusable_run(const AblateArgs& a, const std::string& scene_path,
                                 const std::vector<std::string>& protocols, const fs::path& dir, bool& again) {
  again = false;
  const fs::path prev = dir / "run.json";
  if (!fs::exists(prev)) return std::nullopt;
  try {
    json p = json::parse(read_file_text(prev));
    const bool same = p.at("iters").get<int>() == a.iters && p.value("objects_per_step", 0) == a.objects_per_step;
    // Figures evaluated with another anchor support are not these (--reevaluate evaluates them again).
    bool ok = same && p.value("anchor_support", 0.f) == a.anchor_support;
    for (const auto& proto : protocols)
      for (const char* m : {"object", "pixel"})
        if ((a.mode == "both" || a.mode == m) && !p.at("results").contains(proto + "/" + m)) ok = false;
    if (same && a.reevaluate && fs::exists(dir / "point_cloud.ply")) {  // the kept model, evaluated again
      evaluate_run(a, scene_path, protocols, dir, p);
      ok = again = true;
    }
    if (ok) return p;
  } catch (const Error&) {
    throw;  // an evaluation that failed: its message, not a silent retraining
  } catch (const std::exception&) {
  }
  return std::nullopt;
}

// Adds a run's results to the tally and returns its line for the log (`tag`: how it was obtained, e.g. " (reused)").
std::string record_run(Tally& t, size_t r, const std::string& sname, uint64_t seed, const Row& row, const fs::path& dir,
                       const json& run, const std::string& tag) {
  std::string line = fmt::format("{} seed {} {}{}:", sname, seed, row.name, tag);
  for (auto& [key, v] : run.at("results").items()) {
    if (std::find(t.keys.begin(), t.keys.end(), key) == t.keys.end()) t.keys.push_back(key);
    for (const char* m : {"acc", "miou", "mbiou"})
      t.acc[r][key][m].push_back(v.at(m).is_null() ? NAN : v.at(m).get<double>());
    line += fmt::format("  {} mIoU {} mBIoU {}", key, pct(t.acc[r][key]["miou"].back()),
                        pct(t.acc[r][key]["mbiou"].back()));
  }
  t.runs.push_back({{"scene", sname}, {"seed", seed}, {"row", row.name}, {"dir", dir.string()}, {"run", run}});
  return line;
}

void run_ablate(const AblateArgs& a) {
  set_threads(a.threads);
  if (a.seeds < 1) fail("--seeds: at least 1");
  const std::vector<Scene> scenes = load_scenes(a);
  const std::vector<std::string> protocols = protocols_for(a.protocol, scenes);
  const std::vector<Row> rows = make_rows(a);
  ensure_dir(a.out);
  const int total = int(rows.size() * scenes.size()) * a.seeds;
  Tally tally;
  tally.acc.resize(rows.size());
  int done = 0;
  for (size_t si = 0; si < scenes.size(); ++si) {
    const std::string sname = fs::absolute(a.scenes[si]).lexically_normal().filename().string();
    for (int k = 0; k < a.seeds; ++k) {
      const uint64_t seed = a.seed + uint64_t(k);
      for (size_t r = 0; r < rows.size(); ++r) {
        ++done;
        const fs::path dir = fs::path(a.out) / sname / fmt::format("seed{}", seed) / rows[r].name;
        bool again = false;
        std::optional<json> run = reusable_run(a, a.scenes[si], protocols, dir, again);
        const bool reused = run.has_value();
        if (!reused) {
          ensure_dir(dir);
          run = train_and_evaluate(a, scenes[si], a.scenes[si], rows[r], seed, protocols, dir,
                                   fmt::format("ablate {} {} seed {} ({}/{})", sname, rows[r].name, seed, done, total));
        }
        const std::string line = record_run(tally, r, sname, seed, rows[r], dir, *run,
                                            again    ? " (model reused, evaluated again)"
                                            : reused ? " (reused)"
                                                     : "");
        if (!a.quiet) fmt::print("{}\n", line);
        write_summary(a, scenes.size(), protocols, rows, tally);
      }
    }
  }
  fmt::print("\n{}\nwrote {}/ablation.json and ablation.md\n", write_summary(a, scenes.size(), protocols, rows, tally),
             a.out);
}

CommandRegistration reg(
    {"ablate", "Train and evaluate the OF/SCL/BRO ablation rows of the paper's Table 3", 35, [](CLI::App& sub) {
       auto a = std::make_shared<AblateArgs>();
       sub.add_option("SCENE", a->scenes, "Scene folders with masks/ and features/ (mean and std over scenes x seeds)")
           ->required();
       sub.add_option("--out", a->out, "Output folder")->required();
       sub.add_option("--iters", a->iters, "Iterations per row")->check(CLI::Range(1, 10000000))->capture_default_str();
       sub.add_option("--rows", a->rows,
                      "all (8 rows), ends (all-off and all-on only), middle (the six others), full (the full method "
                      "alone) or leave-one-out (the ends and the three rows with one component off: what each adds "
                      "to the other two), single (the three rows with one component on: with leave-one-out on the "
                      "same --out, all 8); the summaries cover the rows asked, and --rows all on the same --out later "
                      "reuses every run on disk")
           ->check(CLI::IsMember({"all", "ends", "middle", "full", "leave-one-out", "single"}))
           ->capture_default_str();
       sub.add_flag(
           "--reevaluate", a->reevaluate,
           "Runs already on disk (same iterations): evaluate their kept models again with the protocols, modes "
           "and relevancy asked now instead of reusing their figures (after a change in the evaluation)");
       sub.add_flag("--eq15-row", a->eq15_row,
                    "Add the full method trained on eq. 15 alone (--lambda-rgb 0); the other rows keep the default "
                    "full-image photometric loss");
       sub.add_option("--protocol", a->protocol,
                      "a protocol of `hgs eval` (instances, 3d-ovs, lerf-ovs, their -labelled / -scaled variants) or a "
                      "comma-separated list of them; auto = instances when "
                      "gt/instances/ exists, else lerf-ovs")
           ->capture_default_str();
       sub.add_option("--mode", a->mode, "object, pixel or both (query/evaluate.h)")
           ->check(CLI::IsMember({"object", "pixel", "both"}))
           ->capture_default_str();
       sub.add_option("--relevancy", a->relevancy,
                      "Pixel mode: objects (hgs's object-embedding map, not in the paper), objects-lerf, lerf (the "
                      "paper's language map) or foreground (as `hgs eval --relevancy`)")
           ->check(CLI::IsMember({"objects", "objects-lerf", "lerf", "foreground"}))
           ->capture_default_str();
       sub.add_flag("--no-paper-map", a->no_paper_map,
                    "Pixel mode with a --relevancy other than lerf: do not also evaluate the paper's language map "
                    "(by default under <protocol>/pixel-paper-map, with its own tables)");
       sub.add_option("--anchor-support", a->anchor_support,
                      "Object mode: the answer's anchor must render this fraction of its mask id's pixels in the "
                      "training views (as `hgs eval --anchor-support`; a rule of hgs, off by default; 0.25 was chosen "
                      "on the development seeds); runs on disk "
                      "evaluated with another value are not reused (with --reevaluate, evaluated again)")
           ->check(CLI::Range(0.0, 1.0))
           ->capture_default_str();
       sub.add_option("--scl-background", a->scl_background, "As `hgs train --scl-background` (every row)")
           ->check(CLI::IsMember({"auto", "on", "off"}))
           ->capture_default_str();
       sub.add_option("--objects-per-step", a->objects_per_step, "As `hgs train --objects-per-step` (every row)")
           ->check(CLI::Range(0, 65535))
           ->capture_default_str();
       sub.add_option("--seeds", a->seeds, "Training seeds per scene: --seed, --seed + 1, ...")
           ->check(CLI::Range(1, 1000))
           ->capture_default_str();
       sub.add_option("--seed", a->seed, "First training seed")->capture_default_str();
       sub.add_option("--downscale", a->downscale, "Integer image downscale")->check(CLI::Range(1, 64));
       add_threads_option(sub, a->threads);
       sub.add_flag("--quiet", a->quiet, "No progress bars or per-run lines");
       return [a] { run_ablate(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
