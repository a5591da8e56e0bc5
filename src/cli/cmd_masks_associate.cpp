// `hgs masks associate SCENE`: per-view mask ids -> one id per physical object in every view (src/masks/associate.h).
#include <fmt/format.h>

#include <memory>

#include "cli/masks_command.h"
#include "core/error.h"
#include "core/npy.h"
#include "masks/associate.h"
#include "train/depth_model.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

// --depth DIR: DIR/<stem>.npy, z-depth [H, W] (any float dtype NPY reads); a view without a file has none.
std::function<std::vector<float>(const View&)> depth_from_folder(const fs::path& dir) {
  if (!fs::is_directory(dir)) fail("{}: --depth: not a folder (expected <stem>.npy z-depth maps)", dir.string());
  return [dir](const View& v) -> std::vector<float> {
    const fs::path f = dir / (v.stem + ".npy");
    if (!fs::exists(f)) return {};
    NpyArray a = read_npy(f);
    if (a.shape.size() != 2 || a.shape[0] != size_t(v.height) || a.shape[1] != size_t(v.width))
      fail("{}: depth must be [H, W] = [{}, {}] for view {}", f.string(), v.height, v.width, v.name);
    return a.to_float();
  };
}

const char* kDescription =
    "Lifts every view's masks to 3D through COLMAP's 2D-3D correspondences (sparse/0/images.bin: the 3D point\n"
    "each keypoint observes; only keypoints --core-margin px away from mask edges) and links masks of different\n"
    "views that hold the same points. The graph of (view, mask) nodes is clustered greedily by two-way\n"
    "containment (counting only points both views see); two masks of one view never join, except parts: with\n"
    "import.json, parts are folded into a whole they tile, and a group of masks lying inside another object's\n"
    "whole masks joins it. Masks covering more than --max-area of the image are dropped as background, masks\n"
    "with fewer than --min-points 3D points as unliftable, objects seen in fewer than --min-views views as\n"
    "unconfirmed; a left-out mask then joins the object holding most of its 3D points if that object has no\n"
    "mask in its view. Details: docs/formats.md.\n"
    "Writes masks/<stem>.png (object ids, the same in every view), masks/objects.json (names from --names or the\n"
    "input's objects.json by majority, else \"object N\"), masks/associate.json (objects, views per object, what\n"
    "every per-view id became, dropped masks and why); the input is kept in masks/per_view/. With --out-masks DIR\n"
    "everything goes to DIR and the scene is left as it is. Running again needs --force and starts from per_view/.\n"
    "Depth: objects with few COLMAP points (small, textureless) can be linked through dense depth instead:\n"
    "--depth-model M renders each view's depth from a trained model (a short `hgs train SCENE --method rgb\n"
    "--iters 1000 --out M` will do), --depth DIR reads DIR/<stem>.npy z-depth maps [H, W]; every --depth-stride-th\n"
    "pixel is lifted and counts as seen by each other view whose depth agrees within --depth-tolerance.\n"
    "SAM2 tracks (--tracks): the ids are kept along each track in view order, cut where the track's 3D points\n"
    "jump to another object (an identity swap; a merge with a neighbour stays), and the pieces clustered like\n"
    "single masks.\n"
    "Example: hgs masks import SCENE --from sam-json SAM_DIR && hgs masks associate SCENE\n"
    "         hgs masks import SCENE --from sam2-png SAM2_DIR && hgs masks associate SCENE --tracks";

MasksSubcommandRegistration reg(
    {"associate",
     "Make per-view mask ids consistent across views (one id per physical object) through COLMAP's 3D points", 20,
     [](CLI::App& sub) {
       auto o = std::make_shared<masks::AssociateOptions>();
       auto scene = std::make_shared<std::string>(), out = std::make_shared<std::string>(),
            names = std::make_shared<std::string>();
       sub.footer(kDescription);
       sub.add_option("SCENE", *scene, "Scene folder (images/, sparse/0/ with 2D-3D correspondences, masks/)")
           ->required();
       sub.add_option("--out-masks", *out, "Write the associated masks folder here instead of replacing SCENE/masks");
       sub.add_option(
           "--names", *names,
           "Per-view names, JSON {\"<stem>\": {\"<id>\": \"name\"}}; an object takes its masks' most common name");
       sub.add_option(
              "--min-affinity", o->min_affinity,
              "Smallest two-way containment of shared 3D points (geometric mean) for two groups of masks to join")
           ->capture_default_str();
       sub.add_option("--min-views", o->min_views, "Objects seen in fewer views are dropped")->capture_default_str();
       sub.add_option("--min-points", o->min_points, "Masks holding fewer 3D points cannot be lifted and are dropped")
           ->capture_default_str();
       sub.add_option("--core-margin", o->core_margin,
                      "Keypoints closer than this many pixels to a mask's edge do not count (boundary errors)")
           ->check(CLI::Range(0, 64))
           ->capture_default_str();
       sub.add_option("--max-area", o->max_area,
                      "Masks covering a larger fraction of their image are background and dropped")
           ->capture_default_str();
       sub.add_flag(
           "--no-attach", [o](int64_t n) { o->attach = n == 0; },
           "Do not attach left-out masks to the object holding most of their 3D points");
       sub.add_option("--part-fraction", o->part_fraction,
                      "A SAM mask is part of the smallest larger one holding this share of it (re-read from "
                      "import.json's source; 0.9 = import.json's own)")
           ->check(CLI::Range(0.05, 0.9))
           ->capture_default_str();
       sub.add_option("--part-merge", o->part_merge,
                      "A group of masks lying this much inside another object's whole masks (SAM whole + parts) joins "
                      "it as a part")
           ->check(CLI::Range(0.0, 1.0))
           ->capture_default_str();
       sub.add_flag(
           "--part-union", [o](int64_t n) { o->whole_pixels = n == 0; },
           "A part folded into its whole keeps its pixels outside the whole too (default: the whole's outline, "
           "from SAM's masks at import.json's source)");
       sub.add_option(
              "--edge-confidence", o->edge_ramp,
              "Confidence of the written masks ramps from half its score on every mask edge to the full score this "
              "many pixels inside (SAM's files give one score per mask; 0 = keep the input's confidences)")
           ->check(CLI::Range(0, 64))
           ->capture_default_str();
       sub.add_flag(
           "--no-join-parts", [o](int64_t n) { o->join_parts = n == 0; },
           "Do not fold parts into their whole (import.json part_of)");
       sub.add_flag("--drop-surfaces", o->drop_surfaces,
                    "Drop objects whose 3D points spread like a surface (table, floor, walls)");
       sub.add_option("--surface-spread", o->surface_spread,
                      "Spread of an object's 3D points (80th-percentile distance from their median), relative to all "
                      "points', above which it is a surface")
           ->capture_default_str();
       CLI::Option* tracks = sub.add_flag(
           "--tracks", o->tracks,
           "The input's ids are tracks (SAM2 label maps, hgs synth): a mask keeps its track's object unless "
           "the 3D points measure them apart (an id swap); masks with few points ride their track");
       sub.add_option("--track-split", o->track_split,
                      "With --tracks: a mask that neither contains its track's masks so far nor lies inside them (both "
                      "average containments below this) starts a new segment of the track")
           ->check(CLI::Range(0.0, 1.0))
           ->needs(tracks)
           ->capture_default_str();
       auto depth_dir = std::make_shared<std::string>(), depth_model = std::make_shared<std::string>();
       sub.add_option(
           "--depth", *depth_dir,
           "Folder of <stem>.npy z-depth maps [H, W] (0 = none) lifting every mask pixel, not only keypoints");
       sub.add_option("--depth-model", *depth_model,
                      "Render each view's depth from this model (folder with point_cloud.ply, or a PLY)")
           ->excludes(sub.get_option("--depth"));
       sub.add_option("--depth-stride", o->depth_stride,
                      "With depth: lift every Nth pixel in x and y (0 = about 4096 per view)")
           ->check(CLI::Range(0, 256))
           ->capture_default_str();
       sub.add_option("--depth-tolerance", o->depth_tolerance,
                      "With depth: relative depth difference under which another view sees a lifted pixel")
           ->check(CLI::Range(1e-4, 1.0))
           ->capture_default_str();
       sub.add_flag("--force", o->force, "Associate again (from masks/per_view) or replace a non-empty --out-masks");
       sub.add_flag(
           "--quiet", [o](int64_t n) { o->progress = n == 0; }, "No progress bar");
       return [=] {
         o->scene = *scene;
         o->out_masks = *out;
         o->names = *names;
         if (!depth_dir->empty()) o->depth = depth_from_folder(*depth_dir);
         if (!depth_model->empty()) o->depth = train::depth_from_model(*depth_model);
         masks::AssociateSummary s = masks::associate_masks(*o);
         fmt::print("associated {} masks in {} of {} views", s.masks, s.views_with_masks, s.views);
         if (s.joined_parts) fmt::print(" ({} parts folded into their whole)", s.joined_parts);
         fmt::print(": {} objects", s.objects.size());
         if (s.depth_points) fmt::print(" ({} COLMAP points, {} lifted from depth)", s.colmap_points, s.depth_points);
         if (s.attached) fmt::print(" ({} masks attached by their points' votes)", s.attached);
         fmt::print("\n");
         for (auto& ob : s.objects)
           fmt::print("  {:>3}  {:<24} {:>3} views {:>4} masks {:>6} points{}\n", ob.id, ob.name, ob.views, ob.masks,
                      ob.points, ob.surface ? fmt::format("  (surface, spread {:.2f})", ob.spread) : "");
         const int dropped = s.dropped_background + s.dropped_few_points + s.dropped_few_views;
         fmt::print(
             "  dropped {} masks: {} background (> --max-area), {} with too few 3D points, {} in objects seen in too "
             "few views",
             dropped, s.dropped_background, s.dropped_few_points, s.dropped_few_views);
         if (s.dropped_surface) fmt::print(", {} surface objects", s.dropped_surface);
         fmt::print("\n  wrote {}/<stem>.png, objects.json, associate.json", s.out_dir.string());
         if (!s.backup_dir.empty()) fmt::print("; the per-view input is in {}", s.backup_dir.string());
         fmt::print("\n");
       };
     }});

}  // namespace
}  // namespace hgs::cli
