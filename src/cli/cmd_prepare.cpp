// `hgs prepare INPUT --out SCENE [--sam W] [--clip W]`: photos or a video -> a scene `hgs train` reads
// (src/prepare/prepare.h): COLMAP poses, and with weights SAM masks associated across views and CLIP features.
#include <fmt/format.h>

#include "cli/command.h"
#include "cli/sam_options.h"
#include "clip/model.h"
#include "core/error.h"
#include "core/fs.h"
#include "nn/thread_pool.h"
#include "prepare/prepare.h"
#include "prepare/stages.h"
#include "scene/text_embeddings.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct PrepareArgs {
  prepare::PrepareOptions o;
  std::string input, out, sam, clip, phrases_file;
  std::vector<std::string> texts;
  SamModelOptions sam_model;
  int threads = 0;
  bool quiet = false;
};

void run_prepare_command(PrepareArgs& a) {
  set_threads(a.threads);
  prepare::PrepareOptions& o = a.o;
  o.input = a.input, o.scene = a.out;
  o.in.progress = o.pose.progress = o.progress = !a.quiet;
  if (!a.sam.empty()) {
    o.load_sam = [a] { return a.sam_model.load(a.sam); };
    o.sam_key = fmt::format("{} {} {} {}", prepare::hash_file_identity(a.sam), a.sam_model.precision,
                            a.sam_model.vit_heads, a.sam_model.decoder_heads);
  }
  if (!a.clip.empty()) {
    const std::string precision = a.sam_model.precision;
    o.load_clip = [a, precision] {
      clip::ClipModel m = clip::ClipModel::load(a.clip, {});
      if (!m.has_vision) fail("{}: the CLIP model has no vision tower", a.clip);
      m.set_precision(nn::parse_precision(precision, "--precision"));
      return m;
    };
    o.clip_key = fmt::format("{} {}", prepare::hash_file_identity(a.clip), precision);
  }
  o.phrases = a.texts;
  if (!a.phrases_file.empty())
    for (const std::string& p : read_phrase_file(a.phrases_file)) o.phrases.push_back(p);
  prepare::PrepareReport r;
  try {
    r = prepare::run_prepare(o);
  } catch (const fs::filesystem_error& e) {  // one line naming the path, not an internal error
    fail("{}: {}", e.path1().empty() ? a.out : e.path1().string(), e.code().message());
  }
  fmt::print("{}", r.text());
  fmt::print("  report     {}\n", (o.scene / "prepare.json").string());
  if (!o.until.empty()) return;
  if (a.sam.empty())
    fmt::print(
        "  next: hgs train {} --method rgb   (object masks need --sam W: rerun prepare with it, the poses are kept)\n",
        a.out);
  else if (a.clip.empty())
    fmt::print("  next: rerun with --clip W for language features (the poses and masks are kept)\n");
  else fmt::print("  next: hgs train {} --out MODEL && hgs view {} MODEL\n", a.out, a.out);
}

const char* kStages =
    "Stages (each skipped when an earlier run completed it with the same inputs and options; --until STAGE|GROUP\n"
    "stops after it). Costs: 82 photos at 912 px on 2 cores (docs/capture.md \"Cost\"):\n"
    "  input      photos (JPEG/PNG, EXIF orientation applied, --max-size) or video frames (ffmpeg, --fps,\n"
    "             blurred frames dropped) -> SCENE/prepare/input/                       ~1 s\n"
    "  poses      COLMAP (Debian's colmap): features (SIFT), matching (--matcher), mapping (largest model\n"
    "             kept; when fewer than half the images register: retry_mapping, retry_features with\n"
    "             COLMAP's wide-baseline settings), undistort (PINHOLE) -> SCENE/images/,\n"
    "             SCENE/sparse/0/                                                       ~5 min (matching 3.5)\n"
    "  masks      needs --sam: sam (automatic masks of every view), import, depth (--depth-iters RGB steps),\n"
    "             associate (one id per object in every view) -> SCENE/masks/           ~15 s per view + 2 min\n"
    "  language   needs --clip: clip (dense features) -> SCENE/features/, text (--text / --phrases + LERF's\n"
    "             canonical phrases) -> SCENE/text_embeddings.json                       ~2 s per view\n"
    "Every run writes SCENE/prepare.json (images found / registered / dropped, cameras, reprojection error, track\n"
    "length, masks per view, objects, seconds per stage). Work files and logs: SCENE/prepare/.\n"
    "Photos named so COLMAP cannot carry them (backslash, control characters) are renamed (listed); links to\n"
    "nothing are skipped (listed). One run per scene at a time (SCENE/prepare/lock); COLMAP and ffmpeg stop with\n"
    "hgs. Each COLMAP stage checks what it wrote (a full disk fails it, even when COLMAP exits 0).\n"
    "Example: hgs prepare photos/ --out scene --sam sam-vit-b.safetensors --clip clip-vit-b16.safetensors "
    "--text \"red mug\"";

void add_input_options(CLI::App& sub, PrepareArgs& a) {
  sub.add_option("INPUT", a.input, "Folder of photos, or a video file")->required();
  sub.add_option("--out", a.out, "Scene folder to write (new, empty, or made by an earlier hgs prepare)")->required();
  sub.add_option("--max-size", a.o.in.max_size, "Longest image side in pixels; larger photos are downscaled (0 = keep)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1 << 16));
  sub.add_flag("--skip-bad-images", a.o.in.skip_bad,
               "Skip unreadable, empty, truncated or too large image files (listed in the report)");
  sub.add_option("--max-pixels", a.o.in.max_pixels,
                 "Most pixels (width x height) a photo may declare, checked from its header before decoding: a few "
                 "KB of JPEG can declare 16383 x 16383 (1.6 GB decoded). The default holds 108 MP phones and 100 MP "
                 "medium format; decoding holds about this many pixels at once across the threads")
      ->capture_default_str()
      ->check(CLI::Range(int64_t(1), int64_t(1) << 40));
  sub.add_option("--fps", a.o.in.fps, "Video: frames per second to extract")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 240.0));
  sub.add_option("--blur-keep", a.o.in.blur_keep,
                 "Video: drop frames sharper than less than this fraction of their neighbours' median")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  sub.add_option("--ffmpeg", a.o.in.ffmpeg, "ffmpeg program (video input)")->capture_default_str();
}

void add_pose_options(CLI::App& sub, PrepareArgs& a) {
  sub.add_option(
         "--matcher", a.o.pose.matcher,
         fmt::format(
             "auto (sequential for video, exhaustive up to {} photos, else sequential by file name), exhaustive, "
             "sequential, vocab-tree",
             prepare::kExhaustiveUpTo))
      ->check(CLI::IsMember({"auto", "exhaustive", "sequential", "vocab-tree"}))
      ->capture_default_str();
  sub.add_option("--vocab-tree", a.o.pose.vocab_tree, "COLMAP vocabulary tree file (vocab-tree matcher)")
      ->check(CLI::ExistingFile);
  sub.add_option("--camera-model", a.o.pose.camera_model, "COLMAP camera model before undistortion")
      ->check(CLI::IsMember({"SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV"}))
      ->capture_default_str();
  sub.add_option("--max-features", a.o.pose.max_features,
                 "SIFT features per image (matching cost grows with its square)")
      ->capture_default_str()
      ->check(CLI::Range(256, 65536));
  sub.add_flag("--allow-partial", a.o.allow_partial, "Keep going when COLMAP registers fewer than half the images");
  sub.add_option("--colmap", a.o.pose.colmap, "colmap program")->capture_default_str();
}

void add_model_options(CLI::App& sub, PrepareArgs& a) {
  sub.add_option("--sam", a.sam, "SAM weights (.safetensors): masks stage")->check(CLI::ExistingFile);
  sub.add_option("--points-per-side", a.o.amg.points_per_side, "SAM: grid of n x n prompt points per view")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  sub.add_option("--points-per-batch", a.o.amg.points_per_batch, "SAM: points decoded together")
      ->capture_default_str()
      ->check(CLI::Range(1, 4096));
  sub.add_option("--pred-iou-thresh", a.o.amg.pred_iou_thresh, "SAM: keep masks whose predicted IoU is above this")
      ->capture_default_str();
  sub.add_option("--stability-thresh", a.o.amg.stability_score_thresh, "SAM: keep masks whose stability is above this")
      ->capture_default_str();
  sub.add_option("--stability-offset", a.o.amg.stability_score_offset, "SAM: logit offset of the stability score")
      ->capture_default_str();
  sub.add_option("--box-nms-thresh", a.o.amg.box_nms_thresh,
                 "SAM: box IoU above which the lower-scored mask is dropped")
      ->capture_default_str();
  sub.add_option("--min-views", a.o.associate.min_views, "Association: objects seen in fewer views are dropped")
      ->capture_default_str();
  sub.add_flag("--drop-surfaces", a.o.associate.drop_surfaces,
               "Association: drop objects whose 3D points spread like a surface (table, floor, walls)");
  sub.add_option("--depth-iters", a.o.depth_iters,
                 "RGB training steps of the depth model masks are associated through (0 = COLMAP points only)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1 << 20));
  a.sam_model.add_to(sub);
  sub.add_option("--clip", a.clip, "CLIP weights (.safetensors): language stage")->check(CLI::ExistingFile);
  sub.add_option("--input-size", a.o.dense.input_size, "CLIP: shorter image side fed to the ViT")
      ->capture_default_str()
      ->check(CLI::Range(8, 4096));
  sub.add_option("--text", a.texts, "A phrase to embed into text_embeddings.json (repeatable)");
  sub.add_option("--phrases", a.phrases_file, "File with one phrase per line to embed")->check(CLI::ExistingFile);
}

CommandRegistration reg(
    {"prepare", "Photos or a video -> a scene to train: COLMAP poses, SAM masks, CLIP features (resumable)", 3,
     [](CLI::App& sub) {
       auto a = std::make_shared<PrepareArgs>();
       sub.footer(kStages);
       add_input_options(sub, *a);
       add_pose_options(sub, *a);
       add_model_options(sub, *a);
       std::vector<std::string> until{"input", "poses", "masks", "language"};
       for (auto& [s, g] : prepare::stage_groups()) until.push_back(s);
       sub.add_option("--until", a->o.until, "Stop after this stage or group")->check(CLI::IsMember(until));
       add_threads_option(sub, a->threads);
       sub.add_flag("--quiet", a->quiet, "No progress bars");
       return [a] { run_prepare_command(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
