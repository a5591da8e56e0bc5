// SAM (Segment Anything) read from safetensors in the Hugging Face `SamModel` naming or segment-anything's own
// state-dict naming, with the sizes read from the tensors; forward passes in float32 on the CPU, every matrix
// product an OpenBLAS sgemm through src/nn's kernels (linear, layer norm, multi-head attention, GELU), or
// with SamOptions::precision = BF16 the large products in bfloat16 on oneDNN (nn/gemm_bf16.h).
//
//   auto m = hgs::sam::SamModel::load("model.safetensors");
//   hgs::sam::ImageEmbedding e = m.embed(image);                    // preprocessing + ViT + neck
//   hgs::sam::Prompt p; p.points = {{x, y}}; p.labels = {1};        // original image pixels
//   hgs::sam::Prediction r = m.predict(e, p);                        // 4 mask logits + IoU predictions
//   std::vector<float> full = m.upscale_masks(e, r.lowres.data(), 4);   // [4, H, W] logits at the image size
#pragma once
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "core/image.h"
#include "nn/gemm_bf16.h"
#include "nn/transformer.h"

namespace hgs::sam {

using nn::LayerNorm;
using nn::Linear;

enum class Naming { HuggingFace, SegmentAnything };

struct SamOptions {
  // Attention heads of the mask decoder (not visible in the tensor shapes): 0 = `mask_decoder_config.
  // num_attention_heads` of config.json beside the weights if present, else 8 (every released SAM).
  int decoder_heads = 0;
  // Attention heads of each ViT layer: 0 = from the tensors (the layer's attention width / the width of its
  // relative-position tables; for a layer without tables `vision_config.num_attention_heads` of config.json).
  // Given, it must agree with every layer's tables and serves the layers without tables.
  int vit_heads = 0;
  // F32: every product in float32 (the reference path). BF16: the image encoder's and mask decoder's large
  // products in bfloat16 with float32 accumulation (nn/gemm_bf16.h), an approximation; docs/sam.md has its
  // error and speed.
  nn::Precision precision = nn::Precision::F32;
};

// One ViT layer. Its widths are its own (SlimSAM's pruned models differ per layer): attention width
// inner = qkv.out / 3 = heads * head_dim, MLP width fc1.out; only the residual width `hidden` is shared.
struct VitLayer {
  LayerNorm ln1, ln2;
  Linear qkv;                       // [3 * inner, hidden]: rows q, k, v (heads contiguous within each)
  Linear proj;                      // [hidden, inner]
  Linear fc1, fc2;                  // [mlp, hidden], [hidden, mlp]
  std::vector<float> rel_h, rel_w;  // [2 * size - 1, head_dim]; empty = no relative positions
  int window = 0;                   // 0 = global attention over the whole grid
  int heads = 0;                    // 0 = VisionEncoder::heads; scale 1 / sqrt(head_dim)
};

struct VisionEncoder {
  int patch = 0, grid = 0, hidden = 0, out = 0;
  int heads = 0;           // the layers' head count when they all agree (else 0: see VitLayer::heads)
  Linear patch_embed;      // [hidden, 3 * patch * patch], conv weight flattened as (c, ky, kx)
  std::vector<float> pos;  // [grid * grid, hidden]
  std::vector<VitLayer> layers;
  Linear neck1;                  // [out, hidden], zero bias (1x1 conv)
  Linear neck2;                  // [out, 9 * out] flattened as (ky, kx, c), zero bias (3x3 conv, pad 1)
  LayerNorm neck_ln1, neck_ln2;  // channel LayerNorm, eps 1e-6
};

struct PromptEncoder {
  std::vector<float> gauss;                 // [2, C / 2] random Fourier matrix
  std::array<std::vector<float>, 4> point;  // [C] each: negative, positive, box corner 1, box corner 2
  std::vector<float> not_a_point, no_mask;  // [C]
};

struct Attention {
  Linear q, k, v, out;  // [inner, C] x3, [C, inner]
};

struct TwoWayLayer {
  Attention self_attn, token_to_image, image_to_token;
  LayerNorm ln1, ln2, ln3, ln4;
  Linear mlp1, mlp2;  // ReLU between
};

// y = W_n(... ReLU(W_1 x)): SAM's hypernetwork MLPs and IoU head.
struct Mlp {
  std::vector<Linear> layers;
};

// ConvTranspose2d with kernel 2 and stride 2 as one matrix: each input pixel [in] times w [in, 4 * out]
// gives its 2x2 output pixels, columns ordered (dy, dx, out channel).
struct Upconv {
  int in = 0, out = 0;
  std::vector<float> w;            // [in, 4 * out]
  std::vector<float> b;            // [out]
  std::vector<uint16_t> w16 = {};  // [in, 4 * out] w in bfloat16 when the model runs in bf16, else empty
};

struct MaskDecoder {
  int heads = 8, tokens = 4;       // mask tokens (1 single-mask + 3 multimask outputs)
  std::vector<float> iou_token;    // [C]
  std::vector<float> mask_tokens;  // [tokens, C]
  std::vector<TwoWayLayer> layers;
  Attention final_attn;
  LayerNorm ln_final, up_ln;
  Upconv up1, up2;
  std::vector<Mlp> hyper;  // one per mask token: C -> C / 8
  Mlp iou_head;            // C -> tokens
  float ln_eps = 1e-6f;    // two-way blocks: 1e-6 in transformers, 1e-5 in segment-anything
  float ln_final_eps = 1e-5f;
};

// An image after the encoder, with the geometry that prompts and post-processing need.
struct ImageEmbedding {
  int grid = 0, channels = 0;
  std::vector<float> data;       // [grid, grid, C]
  int orig_h = 0, orig_w = 0;    // the image given
  int input_h = 0, input_w = 0;  // after resizing its longest side to image_size() (top-left of the input)
};

// Prompts in original image pixels: points [N, 2] (x, y) with labels (1 foreground, 0 background, -1 ignored)
// and boxes [M, 4] (x0, y0, x1, y1).
struct Prompt {
  std::vector<std::array<float, 2>> points;
  std::vector<int> labels;
  std::vector<std::array<float, 4>> boxes;
};

struct Prediction {
  int tokens = 0, size = 0;   // mask tokens, low-res side (4 * grid)
  std::vector<float> lowres;  // [tokens, size, size] logits (token 0: single mask, 1..3: multimask)
  std::vector<float> iou;     // [tokens]
};

class SamModel {
 public:
  static SamModel load(const std::filesystem::path& path, const SamOptions& opt = {});

  Naming naming = Naming::HuggingFace;
  nn::Precision precision = nn::Precision::F32;
  VisionEncoder vision;
  PromptEncoder prompt;
  MaskDecoder decoder;
  std::filesystem::path path;

  // Rounds the weights of the large products to bfloat16 (BF16) or drops the rounded copies (F32).
  void set_precision(nn::Precision p);

  int image_size() const { return vision.grid * vision.patch; }
  int channels() const { return vision.out; }
  std::string describe() const;  // one line: naming, sizes, windows, global layers

  // --- image encoder ---
  // Resize (longest side to image_size(), antialiased bilinear), ImageNet mean/std, zero padding at the
  // right / bottom: [S, S, 3]; input_h / input_w receive the resized size.
  std::vector<float> preprocess(const Image& img, int* input_h = nullptr, int* input_w = nullptr) const;
  // ViT + neck on x [S, S, 3]: [grid, grid, C]. `stages` (optional) receives the tokens after the patch
  // embedding and after every layer, each [grid, grid, hidden].
  std::vector<float> encode(const float* x, std::vector<std::vector<float>>* stages = nullptr) const;
  ImageEmbedding embed(const Image& img) const;

  // --- prompt encoder ---
  // Sparse prompt embedding [T, C] of points / boxes given in input pixels (after resizing); a padding point
  // is appended when there is no box, as SAM does.
  std::vector<float> encode_prompt(const Prompt& input_pixels) const;
  // The prompt in original pixels scaled to input pixels of `e`.
  Prompt to_input(const ImageEmbedding& e, const Prompt& p) const;
  // Positional encoding of the embedding grid: [grid, grid, C].
  std::vector<float> dense_pe() const;

  // --- mask decoder ---
  // Decodes B prompts of T tokens each, sparse [B, T, C], against the embedding emb [grid, grid, C]:
  // one Prediction per prompt with all mask tokens.
  std::vector<Prediction> decode(const float* emb, const float* sparse, int B, int T) const;
  // One prompt in original pixels, end to end.
  Prediction predict(const ImageEmbedding& e, const Prompt& p) const;

  // --- post-processing ---
  // Low-res logits lowres [n, s, s] -> [n, orig_h, orig_w]: bilinear to image_size(), crop to the input
  // size, bilinear to the original size (align_corners false).
  std::vector<float> upscale_masks(const ImageEmbedding& e, const float* lowres, int n) const;
};

}  // namespace hgs::sam
