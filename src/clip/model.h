// A CLIP model (vision + text towers) read from a safetensors file in open_clip or Hugging Face CLIPModel
// naming, with the architecture inferred from tensor shapes; forward passes run on the CPU in float32 with
// OpenBLAS sgemm for every matrix product (the kernels of nn/transformer.h, the block of block.h).
//
//   auto m = hgs::clip::ClipModel::load("open_clip_model.safetensors");
//   std::vector<float> t = m.embed_text({"a photo of a cat"});   // [T, D], L2-normalised
//   hgs::clip::DenseFeatures f = m.dense_features(image);          // [h, w, D]
#pragma once
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"
#include "nn/gemm_bf16.h"
#include "nn/transformer.h"

namespace hgs::clip {

// The layers and options of a CLIP model are the network runtime's (src/nn).
using nn::Activation;
using nn::LayerNorm;
using nn::Linear;
using nn::Precision;

enum class Naming { OpenClip, HuggingFace };

// "gelu" / "quick_gelu" -> the activation; "auto" or "" -> nullopt. Throws hgs::Error for anything else.
std::optional<Activation> parse_activation(const std::string& s);

struct ClipOptions {
  // Attention heads per tower; 0 = from config.json (HF) / open_clip_config.json beside the weights, else
  // width / 64 (true for every released CLIP ViT).
  int vision_heads = 0, text_heads = 0;
  // Default: from the config file if it names one, else GELU for open_clip naming (LAION models) and
  // QuickGELU for Hugging Face naming (OpenAI models).
  std::optional<Activation> activation;
};

struct Block {
  LayerNorm ln1, ln2;
  Linear qkv;   // [3 * width, width]: rows q, then k, then v
  Linear out;   // [width, width]
  Linear fc;    // [mlp, width]
  Linear proj;  // [width, mlp]
};

struct Transformer {
  int width = 0, heads = 0;
  std::vector<Block> blocks;
};

struct VisionTower {
  int patch = 0, grid = 0;  // native input is grid * patch pixels square
  Linear patch_embed;       // [width, 3 * patch * patch] (conv weight flattened as c, ky, kx), zero bias
  Linear last_value;        // the last block's value rows of qkv: [width, width] (MaskCLIP path)
  std::vector<float> cls;   // [width]
  std::vector<float> pos;   // [grid * grid + 1, width]
  LayerNorm ln_pre, ln_post;
  std::vector<float> proj;  // [width, D]
  Transformer tr;
};

struct TextTower {
  int context = 0, vocab = 0;
  std::vector<float> tok_emb;  // [vocab, width]
  std::vector<float> pos;      // [context, width]
  LayerNorm ln_final;
  std::vector<float> proj;  // [width, D]
  Transformer tr;
};

struct DenseOptions {
  int input_size = 448;   // the image's shorter side is resized to this (then both sides rounded to patches)
  int max_tokens = 2304;  // above this many patches the image is processed in overlapping square tiles
  int tile_size = 0;      // tile side in pixels (0 = input_size); tiles overlap by half a tile
  bool normalize = true;  // L2-normalise each cell's feature
};

struct DenseFeatures {
  int h = 0, w = 0, dim = 0;
  std::vector<float> data;  // [h, w, dim]
};

class ClipModel {
 public:
  static ClipModel load(const std::filesystem::path& path, const ClipOptions& opt = {});

  Naming naming = Naming::OpenClip;
  Activation act = Activation::GELU;
  int embed_dim = 0;
  bool has_vision = false, has_text = false;
  VisionTower vision;
  TextTower text;
  std::filesystem::path path;

  int image_size() const { return vision.grid * vision.patch; }
  std::string describe() const;  // one line: naming, widths, layers, heads, patch, D, activation

  // BF16: the vision tower's linear layers (patch embedding, every block's qkv / out / MLP, the MaskCLIP value
  // path) run in bfloat16 with float32 sums (nn/gemm_bf16.h), an approximation; attention, LayerNorm and the text
  // tower stay float32. F32 (the default) drops the rounded weights again.
  void set_precision(Precision p);
  Precision precision = Precision::F32;

  // --- text ---
  // L2-normalised embeddings of `phrases` (tokenised with Tokenizer::shared()): [T, D].
  std::vector<float> embed_text(const std::vector<std::string>& phrases) const;
  // Same from token ids (each [sot, ..., eot], at most `context` long): [T, D].
  std::vector<float> embed_tokens(const std::vector<std::vector<int>>& ids, bool normalize = true) const;

  // --- image ---
  // CLIP preprocessing (bicubic resize of the shorter side to image_size(), centre crop, mean/std) then the
  // global embedding, L2-normalised: [D].
  std::vector<float> embed_image(const Image& img) const;
  // Global embedding of an already normalised tensor x [H, W, 3] (H, W multiples of the patch; positional
  // embeddings are interpolated when H or W differs from image_size()): [D].
  std::vector<float> embed_image_tensor(const float* x, int H, int W, bool normalize = true) const;
  // MaskCLIP dense features of a normalised tensor x [H, W, 3]: for every patch token the last block's value
  // path v = ln_1(x) Wv + bv through out_proj, ln_post and proj (not normalised): [H/p, W/p, D].
  std::vector<float> dense_tensor(const float* x, int H, int W) const;
  // Dense features of an image in [0, 1] (resize, CLIP mean/std, tiling when large): [h, w, D].
  DenseFeatures dense_features(const Image& img, const DenseOptions& opt = {}) const;

 private:
  // Runs the vision tower on x [H, W, 3]; writes the final tokens [1 + n, width] (after all blocks when
  // `dense` is false) or the dense output [n, D] (when true).
  void vision_forward(const float* x, int H, int W, bool dense, std::vector<float>& out) const;
};

}  // namespace hgs::clip
