// `hgs masks import SCENE --from FORMAT DIR`: SAM / SAM2 / LangSplat outputs -> SCENE/masks/ (src/masks/import.h).
#include <fmt/format.h>

#include "cli/masks_command.h"
#include "masks/import.h"

namespace hgs::cli {
namespace {

const char* kDescription =
    "Writes SCENE/masks/<stem>.png (one label per pixel, per-view ids), masks/<stem>.conf.npy (when the\n"
    "masks carry predicted_iou / stability_score: their product, the paper's zeta) and masks/import.json\n"
    "(per-view list of the source masks). LangSplat input also writes SCENE/features/<stem>.npy.\n"
    "Formats (DIR holds one entry per image, named after the image without its extension):\n"
    "  sam-json   <stem>.json: SAM automatic mask generator list with COCO RLE segmentations\n"
    "  sam-png    <stem>/metadata.csv + <stem>/<id>.png: segment-anything scripts/amg.py folders\n"
    "  sam2-png   <stem>.png: SAM2 label maps, palette (label = palette index) or 8/16-bit grey\n"
    "  langsplat  <name>_s.npy + <name>_f.npy: LangSplat preprocess.py output (language_features/)\n"
    "Overlapping SAM masks: the smallest mask covering a pixel wins (ties: the one listed first).\n"
    "Ids are per view (1 + position in the view's list); they mean nothing across views.\n"
    "Example: hgs masks import SCENE --from langsplat SCENE/language_features --level l";

MasksSubcommandRegistration reg(
    {"import", "Import SAM / SAM2 / LangSplat masks into SCENE/masks/ (and LangSplat features into SCENE/features/)",
     10, [](CLI::App& sub) {
       auto o = std::make_shared<masks::ImportOptions>();
       auto scene = std::make_shared<std::string>(), dir = std::make_shared<std::string>();
       sub.footer(kDescription);
       sub.add_option("SCENE", *scene, "Scene folder (images/, sparse/0/)")->required();
       sub.add_option("--from", o->from, "Input format: sam-json, sam-png, sam2-png or langsplat")
           ->required()
           ->check(CLI::IsMember(masks::import_formats()));
       sub.add_option("DIR", *dir, "Folder with the tool's output")->required();
       auto* level =
           sub.add_option("--level", o->level, "LangSplat level to import: default, s, m or l (langsplat only)")
               ->check(CLI::IsMember({"default", "s", "m", "l"}))
               ->capture_default_str();
       sub.add_option("--feature-stride", o->feature_stride,
                      "LangSplat: feature grid cell in seg-map pixels (1 = exact per-pixel features, large files)")
           ->check(CLI::Range(1, 256))
           ->capture_default_str();
       sub.add_flag("--force", o->force, "Replace an existing masks/ (and features/ with langsplat)");
       sub.add_flag(
           "--quiet", [o](int64_t n) { o->progress = n == 0; }, "No progress bar");
       return [=] {
         o->scene = *scene;
         o->dir = *dir;
         o->level_given = level->count() > 0;
         masks::ImportSummary s = masks::import_masks(*o);
         fmt::print("imported {} of {} views from {} ({}): {} masks", s.imported, s.views, *dir, o->from, s.masks);
         if (s.hidden) fmt::print(" ({} fully covered by smaller masks)", s.hidden);
         fmt::print("\n  wrote {}/masks/<stem>.png{}{}\n", *scene, s.confidence ? " and .conf.npy" : "",
                    s.features ? fmt::format(", {}/features/<stem>.npy ({}x{} grid, D = {})", *scene, s.grid_w,
                                             s.grid_h, s.feature_dim)
                               : "");
         if (o->from != "sam2-png")
           fmt::print(
               "  note: ids are per view (1 + position in each view's list): they do not name the same object across "
               "views\n");
         else
           fmt::print(
               "  note: SAM2's ids are tracks; `hgs masks associate {} --tracks` cuts a track where its 3D points jump "
               "to another object (an id swap) and joins re-born tracks (docs/association.md)\n",
               *scene);
         if (!s.missing.empty())
           fmt::print("  {} views have no masks in {} (first: {})\n", s.missing.size(), *dir, s.missing.front());
       };
     }});

}  // namespace
}  // namespace hgs::cli
