// hgs.synth: the synthetic benchmark scene of `hgs synth` (src/synth): images, COLMAP model, simulated SAM2 masks
// and CLIP features, text embeddings and exact ground truth, written to a folder. The GIL is released meanwhile.
#include "synth/synth.h"
#include "common.h"

namespace hgs::py {

void bind_synth(pb::module_& m) {
  m.def(
      "synth",
      [](const std::filesystem::path& out, const std::string& world, const std::string& preset, uint64_t seed,
         int views, int width, int height, int objects, int points, const std::string& noise, int feature_dim,
         const std::string& mask_ids, const std::string& mask_style, bool surface_masks, bool objects_only,
         double miss_rate, double small_miss_rate, double merge_rate, double split_rate, bool depth, int supersample,
         bool progress) {
        synth::SynthOptions o;
        o.world = world;
        o.preset = preset;
        o.seed = seed;
        o.views = views;
        o.width = width;
        o.height = height;
        o.objects = objects > 0 ? objects : (preset == "room" ? 12 : 8);  // `hgs synth`'s defaults per preset
        o.points = points;
        o.noise = noise;
        o.feature_dim = feature_dim;
        o.mask_ids = mask_ids;
        o.mask_style = mask_style;
        o.surface_masks = surface_masks;
        o.objects_only = objects_only;
        o.miss_rate = miss_rate;
        o.small_miss_rate = small_miss_rate;
        o.merge_rate = merge_rate;
        o.split_rate = split_rate;
        o.write_depth = depth;
        o.supersample = supersample;
        o.progress = progress;
        pb::gil_scoped_release nogil;
        synth::generate(out, o);
        return out.string();
      },
      pb::arg("out"), pb::kw_only(), pb::arg("world") = "realistic", pb::arg("preset") = "tabletop",
      pb::arg("seed") = 1, pb::arg("views") = 48, pb::arg("width") = 320, pb::arg("height") = 240,
      pb::arg("objects") = 0, pb::arg("points") = 30000, pb::arg("noise") = "medium", pb::arg("feature_dim") = 512,
      pb::arg("mask_ids") = "consistent", pb::arg("mask_style") = "label", pb::arg("surface_masks") = true,
      pb::arg("objects_only") = false, pb::arg("miss_rate") = -1.0, pb::arg("small_miss_rate") = -1.0,
      pb::arg("merge_rate") = -1.0, pb::arg("split_rate") = -1.0, pb::arg("depth") = false, pb::arg("supersample") = 2,
      pb::arg("progress") = false,
      "Writes a synthetic benchmark scene to `out` (must not exist or be empty), as `hgs synth` does: world "
      "realistic (CLIP's language statistics, SAM2's failures over the capture order) or simple, preset "
      "tabletop or room, objects 0 = the preset's default (8 / 12), noise none/low/medium/high, mask_ids "
      "consistent/per-view, mask_style label/sam; objects_only = the world without surfaces, small-object misses and "
      "parts; a rate < 0 = the noise level's (docs/formats.md). Returns `out`");
}

}  // namespace hgs::py
