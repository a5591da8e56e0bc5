// `hgs synth`: synthetic benchmark scenes with exact ground truth and simulated 2D foundation-model outputs
// (SAM2-like masks with controlled errors, CLIP-like patch features, text embeddings), written in the scene
// format of docs/formats.md.
#pragma once
#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "core/image.h"
#include "synth/world.h"

namespace hgs::synth {

struct SynthOptions {
  // realistic (the default): CLIP's language statistics and SAM2's failures over the capture order (language.h,
  // tracks.h); simple: near-oracle language features and mask errors drawn afresh in every view (the default
  // world before the realistic one; its scenes are byte for byte those of then).
  std::string world = "realistic";
  std::string preset = "tabletop";
  uint64_t seed = 1;
  int views = 48;
  int width = 320, height = 240;
  int objects = 8;
  int points = 30000;
  std::string noise = "medium";  // none | low | medium | high
  int feature_dim = 512;
  int supersample = 2;  // per-axis samples per pixel for the RGB images
  // What the simulated masks look like (defaults: one consistent id per object, as SAM2 video propagation gives).
  std::string mask_ids = "consistent";  // consistent | per-view (ids shuffled independently in every view, as raw SAM)
  std::string mask_style = "label";     // label (SAM2-like label maps) | sam (overlapping SAM masks, sam/<stem>.json)
  // Label style: the background surfaces (table, floor, walls, shelf) get mask ids K + 1 ... K + S too, as SAM2
  // tracks whatever SAM segmented; objects.json names them. The object masks are the same as without it (the
  // surfaces fill the mask's background pixels that show a surface; they carry no noise of their own). On by
  // default; `--objects-only` turns it off together with the SAM-like errors below (object masks only).
  bool surface_masks = true;
  // SAM's typical errors, each a rate (docs/formats.md); negative = the noise level's rate (NoiseLevel):
  double miss_rate = -1;        // an object missed in a view
  double small_miss_rate = -1;  // added to miss_rate for an object under 0.5 % of the view's pixels
  double merge_rate = -1;       // two touching objects under one mask in a view
  double split_rate = -1;       // an object whose part (its upper half) is a mask of its own
  bool objects_only = false;    // no surfaces, no small-object misses, no parts: the objects-only world
  bool write_depth = false;     // gt/depth/<stem>.npy: exact camera z at pixel centres [H, W] float32 (0 = sky)
  bool progress = true;
};

// Error rates of the simulated SAM2 masks and CLIP features for a noise level.
struct NoiseLevel {
  double miss = 0;        // probability an object is missed in a view
  int jitter = 0;         // max boundary erosion/dilation radius (px)
  double merge = 0;       // probability two touching objects are merged in a view
  double swap = 0;        // probability of an id swap between two objects in a view
  double conf_noise = 0;  // std of per-pixel confidence noise; 0 with `none` (no confidence files written)
  double feature = 0;     // relative norm of the per-patch feature noise
  double small_miss = 0;  // added to miss for an object under kSmallObjectFraction of the view's pixels
  double split = 0;       // probability an object's part is a mask of its own (label style; per object, per scene)
  // The realistic world only (tracks.h, language.h); merge is then per touching pair (drawn once: the pair shares
  // one mask wherever the two touch), swap per touching pair and view (an identity switch that persists), miss 0.
  double lose = 0;           // a track lost in a view (starts a lost run)
  double occluded_lose = 0;  // added to lose when the object's visible area fell below 40 % of its last view's
  double run_mean = 1;       // mean length of a lost run (views, geometric)
  double reborn = 0;         // a lost track comes back under a new id
  int edge_bias = 0;         // max |edge bias| of an object (px, the same in all its views; jitter adds +-1)
  int pieces = 1;            // pieces of every background surface
  double view_bias = 0;      // per-view, per-concept semantic bias of the dense features (x kContent)
  double confusion = 0;      // per-patch mixture of the scene's other concepts (x kContent)
  double patch_noise = 0;    // per-patch isotropic noise (norm)
};
constexpr double kSmallObjectFraction = 0.005;
NoiseLevel noise_level(const std::string& name, const std::string& world = "simple");
// The noise level of `opt.noise` with the options' rate overrides and `objects_only` applied.
NoiseLevel noise_of(const SynthOptions& opt);

// One rendered view: RGB, ground-truth instance ids and camera-space depth at pixel centres.
struct RenderedView {
  std::string name;
  Eigen::Matrix3d R;  // world -> camera
  Eigen::Vector3d t;
  Image rgb;                         // [H, W, 3]
  LabelMap instances;                // [H, W]
  std::vector<float> depth;          // [H, W], 0 where the ray hits nothing
  std::vector<uint16_t> concept_id;  // [H, W] index into the generator's concept list of the surface seen
};

struct Intrinsics {
  int width, height;
  double fx, fy, cx, cy;
};

// Camera poses for the preset (orbit around the table, or inside the room).
std::vector<std::pair<Eigen::Matrix3d, Eigen::Vector3d>> make_poses(const World& w, int n, uint64_t seed);
Intrinsics make_intrinsics(int width, int height);
RenderedView render_view(const World& w, const Intrinsics& K, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                         int supersample, const std::vector<std::string>& concept_names);

// The world point seen at the centre of pixel (x, y) of a rendered view (its depth must be > 0).
Eigen::Vector3d pixel_world_point(const RenderedView& v, const Intrinsics& K, int x, int y);

// Mask pieces both worlds' simulators share (masks.cpp):
// the pairs (a < b) of labels in 1..max_label that are 4-neighbours somewhere in `m`;
std::set<std::pair<int, int>> touching_pairs(const LabelMap& m, int max_label);
// label k's edge moved by r pixels (square element, chessboard distance): r > 0 grows it into unlabelled pixels,
// r < 0 shrinks it, by at most the radius that removes half of it with keep_half;
void shift_edge(LabelMap& m, int k, int r, bool keep_half);
// a simulated confidence [H, W]: 0.45 at label boundaries rising to 1 at 4 px, plus Gaussian noise of std
// `noise`, clamped to [0, 1]; empty when noise <= 0.
std::vector<float> edge_confidence(const LabelMap& mask, double noise, Rng& rng);

// Simulated SAM2 label map for one view and its per-pixel confidence (empty when noise is none).
void simulate_masks(const LabelMap& gt, const NoiseLevel& nl, int num_objects, uint64_t seed, LabelMap& mask,
                    std::vector<float>& confidence);

// --mask-style sam: what SAM's automatic mask generator would give in one view, overlapping and multi-granular:
// every visible object whole, the two halves (split by the world plane x = the object's x) of the objects chosen
// by `split`, and every visible background surface (table, floor, walls). Each mask may be missed or jittered
// (the noise level's rates), masks under 16 px are dropped, and the list is shuffled. `entity` names the truth:
// k = object k, K + 2(k-1) + 1 / + 2 = its first / second half, 3K + c = background surface of concept c.
struct SamMask {
  std::vector<uint8_t> inside;  // [H, W]
  int entity = 0;
  double predicted_iou = 1, stability_score = 1;
};
std::vector<SamMask> simulate_sam_masks(const RenderedView& v, const Intrinsics& K, const World& world,
                                        const std::vector<char>& split, const NoiseLevel& nl, uint64_t seed);

// Unit "concept" vector of a phrase in R^D, fixed by the phrase alone (the same in every scene, like a real text
// encoder).
std::vector<float> concept_vector(const std::string& phrase, int dim);
// The realistic world's MaskCLIP-like dense features on a 16-pixel patch grid (dense_features.cpp):
// [28, 28 W / H, D] (28 cells on the shorter side); contents[c] is image_content of concept c ([D], zero for the
// sky).
std::vector<float> simulate_dense_features(const RenderedView& v, const std::vector<std::vector<float>>& contents,
                                           const NoiseLevel& nl, int dim, uint64_t seed, int& grid_h, int& grid_w);
// Simulated dense CLIP features on a 16-pixel patch grid: [ceil(H/16), ceil(W/16), D].
std::vector<float> simulate_features(const RenderedView& v, const std::vector<std::vector<float>>& concepts,
                                     const std::vector<float>& context, double noise, int dim, uint64_t seed,
                                     int& grid_h, int& grid_w);

// Outer boundary polygons (one per 8-connected part, through the centres of its boundary pixels, as
// cv2.findContours) of the pixels where `inside` is true; filling them as cv2.fillPoly does (eval::fill_polygon)
// gives back each part without holes.
std::vector<std::vector<std::pair<int, int>>> trace_polygons(const std::vector<uint8_t>& inside, int width, int height);

// Generates the whole scene into `out` (created; must not exist or be empty).
void generate(const std::filesystem::path& out, const SynthOptions& opt);

}  // namespace hgs::synth
