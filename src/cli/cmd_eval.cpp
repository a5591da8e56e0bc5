// `hgs eval SCENE MODEL --protocol lerf-ovs|3d-ovs|instances --out report.json`: evaluates a trained hybrid
// model with a benchmark protocol (src/eval/run.h) and writes report.json, report.md and overlay PNGs.
// lerf-ovs reports both the pixel-level (LangSplat's post-processing) and the object-level mode on the same
// frames; 3d-ovs the pixel-level argmax over classes and the object-level one; instances (gt/instances maps) the
// object-level mode and the pixel-level mode (LERF post-processing). --mode picks one (query/evaluate.h). Pixel
// mode's default score (hgs's object-embedding map, not in the paper) comes with the paper's language map beside
// it (mode "pixel-paper-map") unless --no-paper-map.
#include <fmt/format.h>

#include "cli/command.h"
#include "core/error.h"
#include "eval/report.h"
#include "eval/run.h"
#include "query/evaluate.h"
#include "query/query.h"
#include "query/session.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct EvalArgs {
  std::string scene, model, protocol = "instances", out, clip, relevancy = "objects", mode = "both", queries;
  int downscale = 1, threads = 0;
  float mask_threshold = 0.5f, fragment_margin = query::kFragmentMargin, anchor_support = 0.f;
  bool no_png = false, quiet = false, no_paper_map = false;
};

void print_summary(const eval::EvalReport& r) {
  eval::MeanRow m = eval::scene_mean(r);
  auto pct = [](double v) { return std::isnan(v) ? std::string("-") : fmt::format("{:.2f}", 100 * v); };
  // LERF-OVS papers report the localisation accuracy as their accuracy; the pixel accuracy is named apart.
  const bool lerf = r.protocol.starts_with("lerf-ovs");
  fmt::print("{:<10} {:<7} {} {:>6}  mIoU {:>6}  mBIoU {:>6}{}  ({} records)\n", r.protocol, r.mode,
             lerf ? "mAcc(loc)" : "mAcc", pct(eval::paper_accuracy(m, r.protocol)), pct(m.miou), pct(m.mbiou),
             lerf ? fmt::format("  pixel acc {:>6}", pct(m.macc)) : std::string(), m.count);
  const auto c = r.extra.find("miou_ceiling");
  if (c != r.extra.end() && c->is_number() && c->get<double>() < 1)
    fmt::print(
        "           no prediction can score above {} mIoU here (3D-OVS scores a class absent from a frame 0 and "
        "gives unlabelled pixels a class; 3d-ovs-labelled does neither)\n",
        pct(c->get<double>()));
  if (r.protocol == "3d-ovs-labelled")
    fmt::print("           scored on the pixels the ground truth labels and the classes each frame shows\n");
}

// One line on what a mode measures, printed under its figures (so that a newcomer can read them).
std::string what_the_mode_measures(const eval::EvalReport& r) {
  if (r.mode == "object")
    return r.protocol.starts_with("3d-ovs")
               ? "every class takes its best object, every other object (the background too) the class it is "
                 "closest to; a pixel the class of the objects it shows"
               : "every query answered by its best object: mask = that object's rendered opacity > threshold";
  const auto it = r.extra.find("relevancy");
  const std::string score = query::relevancy_description(
      query::parse_relevancy(it != r.extra.end() && it->is_string() ? it->get<std::string>() : "objects"));
  const auto windows = r.extra.find("lerf_windows");
  const bool scaled = windows != r.extra.end() && windows->is_string();
  return r.protocol.starts_with("3d-ovs")
             ? "every pixel on its own: the class that scores highest by " + score
             : "every pixel on its own: " + score +
                   (scaled ? ", LangSplat's post-processing with its 30-px box and 7x7 majority " +
                                 windows->get<std::string>()
                           : ", LangSplat's post-processing (30-px box, min-max, threshold, 7x7 majority)");
}

void run_eval(const EvalArgs& a) {
  set_threads(a.threads);
  fs::path ply = a.model;
  if (fs::is_directory(ply)) ply /= "point_cloud.ply";
  query::Session s(a.scene, ply, a.downscale, a.clip);
  const fs::path out = a.out;
  const fs::path dir = out.parent_path().empty() ? fs::path(".") : out.parent_path();
  query::EvaluateOptions opt;
  opt.protocol = a.protocol;
  opt.object = a.mode != "pixel";
  opt.pixel = a.mode != "object";
  opt.relevancy = query::parse_relevancy(a.relevancy);
  opt.paper_map = !a.no_paper_map;
  opt.object_query.mask_threshold = a.mask_threshold;
  opt.object_query.fragment_margin = a.fragment_margin;
  opt.object_query.anchor_support = a.anchor_support;
  opt.query_set = a.queries;
  if (!a.no_png) opt.overlay_dir = dir / "overlays";
  opt.progress = !a.quiet;
  std::vector<eval::EvalReport> reports = query::evaluate_model(s, opt);
  for (auto& r : reports) r.extra["model"] = ply.string();
  fs::path md = out;
  md.replace_extension(".md");
  eval::write_reports(out, md, reports);
  for (auto& r : reports) {
    print_summary(r);
    fmt::print("  {} mode: {}\n", r.mode, what_the_mode_measures(r));
  }
  fmt::print("wrote {} and {}{}\n", out.string(), md.string(),
             a.no_png ? "" : fmt::format(" (overlays in {})", (dir / "overlays").string()));
}

CommandRegistration reg(
    {"eval", "Evaluate a trained hybrid model: LERF-OVS, 3D-OVS or instance protocol (gt/instances)", 50,
     [](CLI::App& sub) {
       auto a = std::make_shared<EvalArgs>();
       sub.add_option("SCENE", a->scene, "Scene folder (with label/, segmentations/ or gt/instances/)")->required();
       sub.add_option("MODEL", a->model, "Model folder (point_cloud.ply) or PLY file")->required();
       sub.add_option("--protocol", a->protocol,
                      "lerf-ovs, 3d-ovs or instances as their papers score them; 3d-ovs-labelled (3D-OVS on the "
                      "labelled pixels and the classes in view only); lerf-ovs-scaled, instances-scaled (pixel "
                      "mode's 30-px box and 7x7 majority scaled to the image, x width / 1000); see query/evaluate.h")
           ->check(CLI::IsMember(query::protocol_names()))
           ->capture_default_str();
       sub.add_option("--out", a->out, "report.json path (report.md and overlays/ go beside it)")->required();
       sub.add_option("--mode", a->mode,
                      "object (each query's best object; on 3d-ovs every object is classified, the background "
                      "too, see query/evaluate.h), pixel (every pixel scored on a rendered language map; --relevancy; "
                      "with the default, the paper's map beside it) or both")
           ->check(CLI::IsMember({"object", "pixel", "both"}))
           ->capture_default_str();
       sub.add_option("--relevancy", a->relevancy,
                      "Pixel mode, a pixel's score: objects (the text's cosine with hgs's object-embedding map "
                      "sum_k A_k e_k: each object's pooled embedding rendered with its opacity, a rule of this "
                      "project, not in the paper), objects-lerf (LERF's relevancy of that map), lerf (the paper's "
                      "language map, eq. 8 summed over objects = sum_n f_n alpha T, scored with LERF's relevancy as "
                      "LangSplat scores its field) or foreground (lerf times the rendered foreground opacity); see "
                      "query/query.h")
           ->check(CLI::IsMember({"objects", "objects-lerf", "lerf", "foreground"}))
           ->capture_default_str();
       sub.add_option("--queries", a->queries,
                      "Instances protocols: ask the phrases of a query set of SCENE/gt/queries.json instead of the "
                      "objects' names: synonyms (\"coffee cup\"), hypernyms (\"kitchenware\"), attributes (\"the red "
                      "one\") or names; written by `hgs synth` (docs/formats.md)");
       sub.add_flag("--no-paper-map", a->no_paper_map,
                    "Pixel mode with a --relevancy other than lerf: do not also evaluate the paper's language map "
                    "(by default reported beside it as mode pixel-paper-map)");
       sub.add_option("--mask-threshold", a->mask_threshold, "Object mode: mask = rendered object opacity > this")
           ->capture_default_str();
       sub.add_option("--fragment-margin", a->fragment_margin,
                      "Object mode: the answer also takes every label within this cosine of its anchor whose "
                      "Gaussians lie where its Gaussians lie (the fragments SAM2 leaves of one object; a rule of hgs, "
                      "query/fragments.h); 0 = the anchor alone (the best label that holds Gaussians)")
           ->check(CLI::Range(0.0, 2.0))
           ->capture_default_str();
       sub.add_option("--anchor-support", a->anchor_support,
                      "Object mode: the answer's anchor must render, over the training views, at least this fraction "
                      "of the pixels its mask id covers in their masks (a rule of hgs, off by default: a label left "
                      "on a few hidden Gaussians then cannot answer; query/session.h); 0 = off; 0.25 was chosen on the "
                      "development seeds for the rows with one component (docs/ablation.md)")
           ->check(CLI::Range(0.0, 1.0))
           ->capture_default_str();
       sub.add_option("--clip", a->clip, "OpenCLIP weights to embed the query texts");
       sub.add_option("--downscale", a->downscale, "Integer image downscale (as used for training)")
           ->check(CLI::Range(1, 64));
       add_threads_option(sub, a->threads);
       sub.add_flag("--no-png", a->no_png, "Do not write overlay PNGs");
       sub.add_flag("--quiet", a->quiet, "No progress bars");
       return [a] { run_eval(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
