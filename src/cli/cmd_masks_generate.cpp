// `hgs masks generate SCENE --sam W`: SAM's automatic mask generator on every view (src/sam/amg.h), written per
// view as SAM JSON (COCO RLE strings) to SCENE/sam/<stem>.json, the form `hgs masks import --from sam-json` reads.
// A view whose file exists is skipped (resume-safe; --force recomputes); each file is written atomically.
#include <fmt/format.h>

#include "cli/masks_command.h"
#include "cli/sam_options.h"
#include "clip/model.h"
#include "core/error.h"
#include "nn/thread_pool.h"
#include "sam/amg.h"
#include "sam/scene_masks.h"
#include "scene/scene.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct GenerateArgs {
  std::string scene, sam, out;
  sam::AmgOptions amg;
  int downscale = 1, threads = 0;
  SamModelOptions model;  // --vit-heads, --precision, --decoder-heads
  bool force = false, quiet = false;
};

void run_generate(const GenerateArgs& a) {
  nn::set_num_threads(a.threads);
  Scene s = load_scene(a.scene, {a.downscale, false});
  sam::SamModel m = a.model.load(a.sam);
  if (!a.quiet) fmt::print(stderr, "model: {}\n", m.describe());
  const fs::path out_dir = a.out.empty() ? s.root / "sam" : fs::path(a.out);
  sam::SceneMasksSummary r = sam::write_sam_files(s, m, a.amg, out_dir, a.force, !a.quiet);
  fmt::print("wrote {} SAM mask files to {} ({} skipped as already done): {} masks\n", r.written, out_dir.string(),
             r.skipped, r.masks);
  fmt::print("  next: hgs masks import {} --from sam-json {}\n", a.scene, out_dir.string());
}

const char* kDescription =
    "Runs SAM's automatic mask generator (segment-anything's defaults: 32 x 32 grid of points, predicted IoU >\n"
    "0.88, stability score > 0.95 at offset 1, box NMS at 0.7; one crop; --min-region-area 0) on every view\n"
    "and writes SCENE/sam/<stem>.json: [{segmentation: {size, counts (COCO RLE)}, area, bbox, predicted_iou,\n"
    "point_coords, stability_score, crop_box}], sorted by predicted IoU. Views already written are skipped, so an\n"
    "interrupted run resumes. Weights: Hugging Face SamModel or segment-anything .safetensors (docs/sam.md).\n"
    "Example: hgs masks generate SCENE --sam sam-vit-base.safetensors && hgs masks import SCENE --from sam-json "
    "SCENE/sam";

MasksSubcommandRegistration reg(
    {"generate", "Run SAM's automatic mask generator on every view into SCENE/sam/<stem>.json", 5, [](CLI::App& sub) {
       auto a = std::make_shared<GenerateArgs>();
       sub.footer(kDescription);
       sub.add_option("SCENE", a->scene, "Scene folder (images/, sparse/0/)")->required();
       sub.add_option("--sam", a->sam, "SAM weights (.safetensors)")->required()->check(CLI::ExistingFile);
       sub.add_option("--out", a->out, "Output folder (default SCENE/sam)");
       sub.add_option("--points-per-side", a->amg.points_per_side, "Grid of n x n prompt points")
           ->capture_default_str()
           ->check(CLI::Range(1, 256));
       sub.add_option("--points-per-batch", a->amg.points_per_batch, "Points decoded together")
           ->capture_default_str()
           ->check(CLI::Range(1, 4096));
       sub.add_option("--pred-iou-thresh", a->amg.pred_iou_thresh, "Keep masks whose predicted IoU is above this")
           ->capture_default_str();
       sub.add_option("--stability-thresh", a->amg.stability_score_thresh,
                      "Keep masks whose stability score is above this")
           ->capture_default_str();
       sub.add_option("--stability-offset", a->amg.stability_score_offset, "Logit offset of the stability score")
           ->capture_default_str();
       sub.add_option("--box-nms-thresh", a->amg.box_nms_thresh, "Box IoU above which the lower-scored mask is dropped")
           ->capture_default_str();
       sub.add_option(
              "--min-region-area", a->amg.min_mask_region_area,
              "Fill holes and drop islands below this many pixels, then NMS again (0 = off, as segment-anything)")
           ->capture_default_str()
           ->check(CLI::Range(0, 1 << 30));
       sub.add_option("--downscale", a->downscale, "Integer image downscale factor before SAM")
           ->capture_default_str()
           ->check(CLI::Range(1, 64));
       a->model.add_to(sub);
       sub.add_flag("--force", a->force, "Recompute views whose file exists");
       add_threads_option(sub, a->threads);
       sub.add_flag("--quiet", a->quiet, "No progress bar");
       return [a] { run_generate(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
