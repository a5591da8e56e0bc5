// `hgs masks score SCENE [--masks DIR]`: how well a synthetic scene's masks follow its true objects
// (src/eval/association_score.h).
#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "cli/masks_command.h"
#include "core/fs.h"
#include "eval/association_score.h"

namespace hgs::cli {
namespace {

MasksSubcommandRegistration reg(
    {"score", "Synthetic scenes: mean per-view IoU of the masks' objects against gt/instances (ids matched one to one)",
     30, [](CLI::App& sub) {
       auto scene = std::make_shared<std::string>(), dir = std::make_shared<std::string>(),
            out = std::make_shared<std::string>();
       auto min_px = std::make_shared<int>(16);
       auto test_only = std::make_shared<bool>(false);
       sub.footer(
           "Matches mask ids to the true objects of gt/instances one to one (greedy on the sum over views of their "
           "IoU),\n"
           "then averages, over every (view, object) pair where the object covers at least --min-pixels, the IoU of\n"
           "its matched id's mask (0 when unmatched) and its boundary IoU (the evaluation's band, 2 % of the\n"
           "diagonal). Prints the mean IoU over pairs, the mean over objects, the fraction of pairs with IoU >= 0.5,\n"
           "and the mean boundary IoU over all pairs and over those with IoU >= 0.5 (the mask found the object).");
       sub.add_option("SCENE", *scene, "Synthetic scene folder (gt/instances/)")->required();
       sub.add_option("--masks", *dir, "Folder of <stem>.png label maps (default SCENE/masks)");
       sub.add_option("--min-pixels", *min_px, "Objects smaller than this in a view are not scored there")
           ->capture_default_str();
       sub.add_option("--json", *out, "Also write the figures to this JSON file");
       sub.add_flag("--test-views", *test_only, "Score the test views only (those `hgs eval` scores a model on)");
       return [=] {
         const std::filesystem::path d =
             dir->empty() ? std::filesystem::path(*scene) / "masks" : std::filesystem::path(*dir);
         eval::AssociationScore s = eval::score_association(*scene, d, *min_px, *test_only);
         fmt::print(
             "{}: {} views, {} (view, object) pairs: mean IoU {:.4f}, per-object mean {:.4f}, IoU >= 0.5 in {:.1f}%\n",
             d.string(), s.views, s.pairs, s.mean_iou, s.object_mean_iou, 100 * s.pairs_above_half);
         fmt::print("  boundary IoU: mean {:.4f}, {:.4f} where the mask found the object (IoU >= 0.5)\n", s.mean_biou,
                    s.found_mean_biou);
         if (!out->empty()) {
           nlohmann::json j = {{"masks", d.string()},
                               {"views", s.views},
                               {"pairs", s.pairs},
                               {"mean_iou", s.mean_iou},
                               {"object_mean_iou", s.object_mean_iou},
                               {"pairs_above_half", s.pairs_above_half},
                               {"mean_biou", s.mean_biou},
                               {"found_mean_biou", s.found_mean_biou}};
           for (auto& [g, p] : s.match) j["match"][std::to_string(g)] = p;
           for (auto& [g, v] : s.object_iou) j["object_iou"][std::to_string(g)] = v;
           atomic_write_text(*out, j.dump(1) + "\n");
         }
       };
     }});

}  // namespace
}  // namespace hgs::cli
