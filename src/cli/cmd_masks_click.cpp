// `hgs masks click SCENE --sam W --view V --point x,y`: one SAM mask from point / box prompts on one view,
// written as an 8-bit PNG (255 inside) at the view's size.
#include <fmt/format.h>

#include "cli/masks_command.h"
#include "cli/sam_options.h"
#include "clip/model.h"
#include "core/error.h"
#include "core/fs.h"
#include "nn/thread_pool.h"
#include "sam/model.h"
#include "scene/scene.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct ClickArgs {
  std::string scene, sam, view, out;
  std::vector<std::string> points, negatives, boxes;
  int downscale = 1, threads = 0;
  SamModelOptions model;  // --vit-heads, --precision, --decoder-heads
  bool single = false;
};

std::vector<float> parse_numbers(const std::string& s, size_t n, const char* what) {
  std::vector<float> v;
  size_t p = 0;
  while (p <= s.size()) {
    size_t q = s.find(',', p);
    if (q == std::string::npos) q = s.size();
    const std::string tok = s.substr(p, q - p);
    try {
      size_t used = 0;
      v.push_back(std::stof(tok, &used));
      if (used != tok.size()) throw std::invalid_argument(tok);
    } catch (const std::exception&) {
      fail("{} \"{}\": \"{}\" is not a number", what, s, tok);
    }
    p = q + 1;
  }
  if (v.size() != n) fail("{} \"{}\": expected {} comma-separated numbers", what, s, n);
  return v;
}

int find_view(const Scene& s, const std::string& v) {
  for (const View& w : s.views)
    if (w.name == v || w.stem == v) return w.index;
  if (!v.empty() && v.find_first_not_of("0123456789") == std::string::npos) {
    const long i = std::stol(v);
    if (i < long(s.views.size())) return int(i);
  }
  fail("--view {}: no such view in {} (a name, stem or index below {})", v, s.root.string(), s.views.size());
}

void run_click(const ClickArgs& a) {
  nn::set_num_threads(a.threads);
  Scene s = load_scene(a.scene, {a.downscale, false});
  const int vi = find_view(s, a.view);
  sam::Prompt p;
  for (const auto& t : a.points) {
    auto v = parse_numbers(t, 2, "--point");
    p.points.push_back({v[0], v[1]});
    p.labels.push_back(1);
  }
  for (const auto& t : a.negatives) {
    auto v = parse_numbers(t, 2, "--negative");
    p.points.push_back({v[0], v[1]});
    p.labels.push_back(0);
  }
  for (const auto& t : a.boxes) {
    auto v = parse_numbers(t, 4, "--box");
    p.boxes.push_back({v[0], v[1], v[2], v[3]});
  }
  if (p.points.empty() && p.boxes.empty()) fail("masks click: give at least one --point, --negative or --box");
  sam::SamModel m = a.model.load(a.sam);
  Image img = s.load_image(vi);
  sam::ImageEmbedding e = m.embed(img);
  sam::Prediction r = m.predict(e, p);
  // segment-anything's predictor: the single-mask output, or the best of the three multimask outputs.
  int best = 0;
  if (!a.single && r.tokens > 1) {
    best = 1;
    for (int t = 2; t < r.tokens; ++t)
      if (r.iou[t] > r.iou[best]) best = t;
  }
  std::vector<float> full = m.upscale_masks(e, r.lowres.data() + size_t(best) * r.size * r.size, 1);
  Image out(img.width, img.height, 1);
  long area = 0;
  for (size_t i = 0; i < full.size(); ++i) {
    out.px[i] = full[i] > 0.f ? 1.f : 0.f;
    area += full[i] > 0.f;
  }
  const fs::path path = a.out.empty() ? fs::path(s.views[vi].stem + "_mask.png") : fs::path(a.out);
  if (path.has_parent_path()) ensure_dir(path.parent_path());
  save_png(path, out);
  fmt::print("view {} ({}x{}): {} output {}, predicted IoU {:.3f}, {} pixels -> {}\n", s.views[vi].name, img.width,
             img.height, a.single ? "single-mask" : "multimask", best, r.iou[best], area, path.string());
}

MasksSubcommandRegistration reg(
    {"click", "One SAM mask from point / box prompts on one view (PNG)", 6, [](CLI::App& sub) {
       auto a = std::make_shared<ClickArgs>();
       sub.footer(
           "Coordinates are pixels of the view as loaded (after --downscale). Without --single the best of\n"
           "SAM's three multimask outputs (highest predicted IoU) is written, as segment-anything's predictor does.\n"
           "Example: hgs masks click SCENE --sam sam-vit-base.safetensors --view 0 --point 320,240 --out mug.png");
       sub.add_option("SCENE", a->scene, "Scene folder (images/, sparse/0/)")->required();
       sub.add_option("--sam", a->sam, "SAM weights (.safetensors)")->required()->check(CLI::ExistingFile);
       sub.add_option("--view", a->view, "View name, stem or index")->required();
       sub.add_option("--point", a->points, "Foreground point x,y (repeatable)");
       sub.add_option("--negative", a->negatives, "Background point x,y (repeatable)");
       sub.add_option("--box", a->boxes, "Box x0,y0,x1,y1 (repeatable)");
       sub.add_flag("--single", a->single, "Use SAM's single-mask output");
       sub.add_option("--out", a->out, "Output PNG (default <stem>_mask.png)");
       sub.add_option("--downscale", a->downscale, "Integer image downscale factor")
           ->capture_default_str()
           ->check(CLI::Range(1, 64));
       a->model.add_to(sub);
       add_threads_option(sub, a->threads);
       return [a] { run_click(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
