// `hgs features SCENE --clip W`: dense CLIP (MaskCLIP) features of every view, written to
// SCENE/features/<stem>.npy as float16 [h, w, D], L2-normalised per patch.
#include <fmt/format.h>

#include "cli/command.h"
#include "clip/model.h"
#include "clip/scene_features.h"
#include "core/error.h"
#include "nn/thread_pool.h"
#include "scene/scene.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct FeaturesArgs {
  std::string scene, clip, act = "auto", precision = "f32";
  int input_size = 448, downscale = 1, tile = 0, max_tokens = 2304, threads = 0;
  bool raw = false, skip_existing = false, quiet = false;
};

void run_features(const FeaturesArgs& a) {
  nn::set_num_threads(a.threads);
  Scene s = load_scene(a.scene, {a.downscale, false});
  clip::ClipOptions opt;
  opt.activation = clip::parse_activation(a.act);
  clip::ClipModel m = clip::ClipModel::load(a.clip, opt);
  if (!m.has_vision) fail("{}: the model has no vision tower", a.clip);
  m.set_precision(nn::parse_precision(a.precision, "--precision"));
  if (!a.quiet) fmt::print(stderr, "model: {}\n", m.describe());
  clip::DenseOptions d;
  d.input_size = a.input_size;
  d.tile_size = a.tile;
  d.max_tokens = a.max_tokens;
  d.normalize = !a.raw;
  if (d.input_size < m.vision.patch)
    fail("--input-size {} is smaller than the patch size {}", d.input_size, m.vision.patch);
  const fs::path out_dir = s.root / "features";
  clip::SceneFeaturesSummary r = clip::write_clip_features(s, m, d, !a.skip_existing, !a.quiet);
  fmt::print("wrote {} feature maps to {} ({} skipped; D = {}{})\n", r.written, out_dir.string(), r.skipped,
             m.embed_dim, r.grid_h ? fmt::format(", last grid {}x{}", r.grid_w, r.grid_h) : "");
}

CommandRegistration reg(
    {"features", "Extract dense CLIP (MaskCLIP) features of every view into SCENE/features/", 25, [](CLI::App& sub) {
       auto a = std::make_shared<FeaturesArgs>();
       sub.add_option("SCENE", a->scene, "Scene folder (images/, sparse/0/)")->required();
       sub.add_option("--clip", a->clip, "CLIP weights (.safetensors, open_clip or Hugging Face naming)")
           ->required()
           ->check(CLI::ExistingFile);
       sub.add_option("--input-size", a->input_size,
                      "Shorter image side fed to the ViT, in pixels (grid = size / patch)")
           ->capture_default_str()
           ->check(CLI::Range(8, 4096));
       sub.add_option("--downscale", a->downscale, "Integer image downscale factor before extraction")
           ->capture_default_str()
           ->check(CLI::Range(1, 64));
       sub.add_option("--max-tokens", a->max_tokens, "Above this many patches, run overlapping square tiles")
           ->capture_default_str()
           ->check(CLI::Range(1, 1 << 20));
       sub.add_option("--tile", a->tile, "Tile side in pixels when tiling (0 = --input-size)")->capture_default_str();
       sub.add_flag("--raw", a->raw, "Do not L2-normalise the features");
       sub.add_flag("--skip-existing", a->skip_existing, "Keep feature files that already exist");
       sub.add_option("--act", a->act, "Activation: auto, gelu, quick_gelu")->capture_default_str();
       sub.add_option("--precision", a->precision,
                      "f32 (exact) or bf16: the vision tower's linear layers in bfloat16 with "
                      "float32 sums, faster with AMX / AVX512-BF16 (an approximation: docs/clip.md)")
           ->check(CLI::IsMember({"f32", "bf16"}))
           ->capture_default_str();
       add_threads_option(sub, a->threads);
       sub.add_flag("--quiet", a->quiet, "No progress bar");
       return [a] { run_features(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
