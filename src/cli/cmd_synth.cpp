// `hgs synth`: generate a synthetic benchmark scene with exact ground truth (see src/synth/synth.h).
#include <fmt/format.h>

#include <chrono>

#include "cli/command.h"
#include "synth/synth.h"

namespace hgs::cli {
namespace {

CommandRegistration reg(
    {"synth",
     "Generate a synthetic benchmark scene (images, COLMAP model, simulated SAM2 masks and CLIP features, labels)", 10,
     [](CLI::App& sub) {
       auto o = std::make_shared<synth::SynthOptions>();
       auto out = std::make_shared<std::string>();
       auto threads = std::make_shared<int>(0);
       sub.add_option("--out", *out, "Output scene folder (must not exist or be empty)")->required();
       sub.add_option("--world", o->world,
                      "realistic (CLIP's language statistics, SAM2's failures over the capture order; query sets in "
                      "gt/queries.json) or simple (near-oracle language, mask errors drawn afresh in every view: the "
                      "default world before the realistic one); docs/formats.md")
           ->check(CLI::IsMember({"realistic", "simple"}))
           ->capture_default_str();
       sub.add_option("--preset", o->preset, "Scene layout: tabletop or room")
           ->check(CLI::IsMember({"tabletop", "room"}))
           ->capture_default_str();
       sub.add_option("--seed", o->seed, "Random seed (same seed, same bytes)")
           ->check(CLI::Validator(
               [](std::string& v) {
                 return v.find_first_not_of("0123456789") == std::string::npos && !v.empty() && v.size() <= 19
                            ? std::string()
                            : "must be an integer between 0 and 10^19 - 1, got " + v;
               },
               "INT >= 0"))
           ->capture_default_str();
       sub.add_option("--views", o->views, "Number of views")->capture_default_str();
       sub.add_option("--width", o->width, "Image width")->capture_default_str();
       sub.add_option("--height", o->height, "Image height")->capture_default_str();
       auto* objects =
           sub.add_option("--objects", o->objects, "Number of objects K (default 8 for tabletop, 12 for room)");
       sub.add_option("--points", o->points, "Number of SfM points")->capture_default_str();
       sub.add_option("--noise", o->noise, "Simulated 2D-model error level: none, low, medium, high")
           ->check(CLI::IsMember({"none", "low", "medium", "high"}))
           ->capture_default_str();
       sub.add_option("--feature-dim", o->feature_dim, "Language feature dimension D")->capture_default_str();
       sub.add_option("--mask-ids", o->mask_ids,
                      "Mask ids: consistent (one id per object in every view, as SAM2 propagation gives) or per-view "
                      "(shuffled in every view, as raw SAM gives; truth in gt/mask_ids.json, no masks/objects.json)")
           ->check(CLI::IsMember({"consistent", "per-view"}))
           ->capture_default_str();
       sub.add_option(
              "--mask-style", o->mask_style,
              "Masks: label (SAM2-like label maps) or sam (overlapping SAM masks: wholes, halves, background surfaces, "
              "as SAM JSON with COCO RLE in sam/<stem>.json; masks/ holds them flattened as `hgs masks import` does)")
           ->check(CLI::IsMember({"label", "sam"}))
           ->capture_default_str();
       auto* surfaces =
           sub.add_flag("--surface-masks", o->surface_masks,
                        "(The default) Label-style masks also hold the background surfaces (table, floor, walls) as "
                        "objects K+1.., named in objects.json, as SAM2 propagation of everything SAM segmented gives");
       sub.add_flag("--objects-only", o->objects_only,
                    "The world of earlier versions: masks of the objects only (no surfaces), no small-object misses, "
                    "no parts; for comparisons")
           ->excludes(surfaces);
       auto rate = [&](const char* name, double& v, const char* what) {
         sub.add_option(name, v, std::string(what) + " (default: the noise level's rate, docs/formats.md)")
             ->check(CLI::Range(0.0, 1.0));
       };
       rate("--miss-rate", o->miss_rate,
            "Probability that an object is missed in a view (realistic world: that its track is lost, for a run of "
            "views)");
       rate("--small-miss-rate", o->small_miss_rate,
            "Added to --miss-rate for an object under 0.5 % of the view's pixels (SAM misses small objects)");
       rate("--merge-rate", o->merge_rate,
            "Probability that two touching objects share one mask in a view (realistic world: that SAM confuses a "
            "touching pair, which then shares one mask wherever the two touch)");
       rate("--split-rate", o->split_rate,
            "Probability that an object's part (its upper half) is a mask of its own, in every view (label "
            "style; SAM cuts parts off wholes and SAM2 tracks them)");
       sub.add_flag(
           "--depth", o->write_depth,
           "Also write the exact depth of every view, gt/depth/<stem>.npy (camera z [H, W], float32; 0 = nothing)");
       sub.add_option("--supersample", o->supersample, "Samples per pixel per axis for the RGB images")
           ->check(CLI::Range(1, 8))
           ->capture_default_str();
       add_threads_option(sub, *threads);
       sub.add_flag(
           "--quiet", [o](int64_t n) { o->progress = n == 0; }, "No progress bars");
       return [=] {
         set_threads(*threads);
         if (objects->count() == 0 && o->preset == "room") o->objects = 12;
         auto t0 = std::chrono::steady_clock::now();
         synth::generate(*out, *o);
         double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
         fmt::print("wrote {} ({} preset, {} views {}x{}, {} objects, {} points, noise {}, D = {}) in {:.1f}s\n", *out,
                    o->preset, o->views, o->width, o->height, o->objects, o->points, o->noise, o->feature_dim, s);
       };
     }});

}  // namespace
}  // namespace hgs::cli
