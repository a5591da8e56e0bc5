// Loading SAM from safetensors: detects the naming (Hugging Face SamModel or segment-anything), reads every size
// from the tensor shapes (ViT width, depth, each layer's own attention width, heads (attention width / the
// relative-position width) and MLP width, window size and global layers from each layer's relative-position length,
// patch, grid, neck / decoder widths, MLP depths), converts to float32 in one layout (Linear [out, in], convolutions as
// matrices for HWC tensors) and checks every shape: a missing or mis-shaped tensor is a one-line error naming the file
// and the tensor.
#include <fmt/format.h>

#include <algorithm>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/json_file.h"
#include "nn/safetensors.h"
#include "nn/transformer.h"
#include "sam/model.h"

namespace hgs::sam {
namespace {
namespace fs = std::filesystem;
using nn::SafeTensors;
using nn::shape_str;

void replace_all(std::string& s, const std::string& a, const std::string& b) {
  for (size_t p = s.find(a); p != std::string::npos; p = s.find(a, p + b.size())) s.replace(p, a.size(), b);
}

// segment-anything's name of a tensor given its Hugging Face name (MLP heads are mapped by the caller).
std::string sa_name(std::string n) {
  if (n == "shared_image_embedding.positional_embedding")
    return "prompt_encoder.pe_layer.positional_encoding_gaussian_matrix";
  replace_all(n, "vision_encoder.", "image_encoder.");
  replace_all(n, "patch_embed.projection.", "patch_embed.proj.");
  replace_all(n, "image_encoder.layers.", "image_encoder.blocks.");
  replace_all(n, "neck.conv1.", "neck.0.");
  replace_all(n, "neck.layer_norm1.", "neck.1.");
  replace_all(n, "neck.conv2.", "neck.2.");
  replace_all(n, "neck.layer_norm2.", "neck.3.");
  replace_all(n, "prompt_encoder.point_embed.", "prompt_encoder.point_embeddings.");
  replace_all(n, "layer_norm_final_attn.", "norm_final_attn.");
  replace_all(n, "upscale_conv1.", "output_upscaling.0.");
  replace_all(n, "upscale_layer_norm.", "output_upscaling.1.");
  replace_all(n, "upscale_conv2.", "output_upscaling.3.");
  for (int i = 1; i <= 4; ++i) replace_all(n, fmt::format(".layer_norm{}.", i), fmt::format(".norm{}.", i));
  return n;
}

struct Loader {
  const SafeTensors& st;
  Naming naming;
  bool data_parallel = false;  // segment-anything names under 'image_encoder.module.' (SlimSAM's DataParallel encoder)
  std::string file() const { return st.path().string(); }
  std::string key(const std::string& hf) const {
    if (naming == Naming::HuggingFace) return hf;
    std::string n = sa_name(hf);
    if (data_parallel && n.rfind("image_encoder.", 0) == 0) n.insert(14, "module.");
    return n;
  }
  bool has(const std::string& hf) const { return st.has(key(hf)); }

  std::vector<float> get(const std::string& hf, const std::vector<int64_t>& shape) const {
    return st.to_float(key(hf), shape);
  }
  std::vector<int64_t> shape(const std::string& hf) const { return st.info(key(hf)).shape; }
  int64_t dim(const std::string& hf, size_t i) const {
    auto s = shape(hf);
    if (s.size() <= i) fail("{}: tensor '{}' has shape {}, too few dimensions", file(), key(hf), shape_str(s));
    return s[i];
  }
  LayerNorm ln(const std::string& p, int c) const { return {get(p + ".weight", {c}), get(p + ".bias", {c})}; }
  Linear lin(const std::string& p, int out, int in) const {
    return {in, out, get(p + ".weight", {out, in}), get(p + ".bias", {out})};
  }
  int count(const std::string& prefix, const std::string& probe) const {
    int n = 0;
    while (has(fmt::format("{}{}.{}", prefix, n, probe))) ++n;
    return n;
  }
  // A ReLU MLP: HF proj_in, layers.0.., proj_out; segment-anything layers.0..n-1.
  Mlp mlp(const std::string& p, int in, int out) const {
    std::vector<std::string> names;
    if (naming == Naming::HuggingFace) {
      names.push_back(p + ".proj_in");
      for (int j = 0; has(fmt::format("{}.layers.{}.weight", p, j)); ++j)
        names.push_back(fmt::format("{}.layers.{}", p, j));
      names.push_back(p + ".proj_out");
    } else {
      for (int j = 0; st.has(fmt::format("{}.layers.{}.weight", key(p), j)); ++j)
        names.push_back(fmt::format("{}.layers.{}", p, j));
      if (names.size() < 2) fail("{}: MLP '{}.layers.N' not found or shorter than 2 layers", file(), key(p));
    }
    Mlp m;
    int d = in;
    for (size_t j = 0; j < names.size(); ++j) {
      const int o = j + 1 == names.size() ? out : int(dim(names[j] + ".weight", 0));
      m.layers.push_back(lin(names[j], o, d));
      d = o;
    }
    return m;
  }
  Attention attn(const std::string& p, int c) const {
    const int inner = int(dim(p + ".q_proj.weight", 0));
    return {lin(p + ".q_proj", inner, c), lin(p + ".k_proj", inner, c), lin(p + ".v_proj", inner, c),
            lin(p + ".out_proj", c, inner)};
  }
  // ConvTranspose2d(in, out, 2, stride 2) weight [in, out, 2, 2] -> [in, (dy, dx, out)].
  Upconv upconv(const std::string& p, int in, int out) const {
    auto w = get(p + ".weight", {in, out, 2, 2});
    Upconv u{in, out, std::vector<float>(w.size()), get(p + ".bias", {out})};
    for (int i = 0; i < in; ++i)
      for (int o = 0; o < out; ++o)
        for (int d = 0; d < 4; ++d) u.w[size_t(i) * 4 * out + d * out + o] = w[(size_t(i) * out + o) * 4 + d];
    return u;
  }
  std::vector<float> vec(const std::string& hf, int c) const { return get(hf, {1, c}); }
};

// What config.json beside the weights says about the shapes that do not show in the tensors (0 / empty =
// not given): the decoder's head count and, for ViT layers without relative-position tables, the encoder's head
// count, window size and global layers (Hugging Face SamVisionConfig).
struct ConfigHints {
  int decoder_heads = 0, vit_heads = 0, window = 0;
  std::vector<int> global_layers;
  bool has_vision = false;
};

ConfigHints read_config(const fs::path& weights) {
  ConfigHints h;
  fs::path cfg = (weights.parent_path().empty() ? fs::path(".") : weights.parent_path()) / "config.json";
  if (!fs::is_regular_file(cfg)) return h;
  try {
    nlohmann::json j = read_json_file(cfg);
    if (j.contains("mask_decoder_config") && j["mask_decoder_config"].contains("num_attention_heads"))
      h.decoder_heads = j["mask_decoder_config"]["num_attention_heads"].get<int>();
    if (j.contains("vision_config")) {
      const nlohmann::json& v = j["vision_config"];
      h.has_vision = v.contains("window_size") && v.contains("global_attn_indexes");
      if (v.contains("num_attention_heads")) h.vit_heads = v["num_attention_heads"].get<int>();
      if (v.contains("window_size")) h.window = v["window_size"].get<int>();
      if (v.contains("global_attn_indexes")) h.global_layers = v["global_attn_indexes"].get<std::vector<int>>();
    }
  } catch (const nlohmann::json::exception& e) {
    fail("{}: cannot read the model config beside the weights ({})", cfg.string(), e.what());
  }
  return h;
}

// Every size of a layer comes from its own tensors (SlimSAM prunes each layer's head dimension and MLP width
// independently; the residual width C is the encoder's): attention width I from qkv [3 I, C] (and proj
// [C, I]), head dim from the relative-position tables [2 s - 1, hd], heads = I / hd, window s, MLP width from
// lin1 [mlp, C] (and lin2 [C, mlp]).
void load_vision(const Loader& L, const ConfigHints& cfg, int given_heads, VisionEncoder& v) {
  const std::string file = L.file();
  const std::string conv = "vision_encoder.patch_embed.projection.weight";
  auto cs = L.shape(conv);
  if (cs.size() != 4 || cs[1] != 3 || cs[2] != cs[3])
    fail("{}: tensor '{}' has shape {}, expected [hidden, 3, patch, patch]", file, L.key(conv), shape_str(cs));
  v.hidden = int(cs[0]);
  v.patch = int(cs[2]);
  const int C = v.hidden, P = v.patch;
  v.patch_embed = {3 * P * P, C, L.get(conv, {C, 3, P, P}), L.get("vision_encoder.patch_embed.projection.bias", {C})};
  v.grid = int(L.dim("vision_encoder.pos_embed", 1));
  v.pos = L.get("vision_encoder.pos_embed", {1, v.grid, v.grid, C});
  const int n = L.count("vision_encoder.layers.", "layer_norm1.weight");
  if (n == 0) fail("{}: no ViT layers found ('{}')", file, L.key("vision_encoder.layers.0.layer_norm1.weight"));
  for (int i = 0; i < n; ++i) {
    const std::string p = fmt::format("vision_encoder.layers.{}.", i);
    VitLayer l;
    // qkv [3 I, C], or SlimSAM's separate q, k, v [I, C] each (its pruning code splits them), concatenated.
    const bool split = !L.has(p + "attn.qkv.weight") && L.has(p + "attn.q.weight");
    const std::string qkv = p + (split ? "attn.q.weight" : "attn.qkv.weight");
    const int64_t rows = L.dim(qkv, 0);
    if (rows <= 0 || (!split && rows % 3))
      fail("{}: tensor '{}' has shape {}, expected [3 * attention width, {}]", file, L.key(qkv),
           shape_str(L.shape(qkv)), C);
    const int I = int(split ? rows : rows / 3);
    if (split) {
      l.qkv = {C, 3 * I, {}, {}};
      for (const char* part : {"attn.q", "attn.k", "attn.v"}) {
        Linear x = L.lin(p + part, I, C);
        l.qkv.w.insert(l.qkv.w.end(), x.w.begin(), x.w.end());
        l.qkv.b.insert(l.qkv.b.end(), x.b.begin(), x.b.end());
      }
    } else {
      l.qkv = L.lin(p + "attn.qkv", 3 * I, C);
    }
    l.proj = L.lin(p + "attn.proj", C, I);
    const std::string rh = p + "attn.rel_pos_h", rw = p + "attn.rel_pos_w";
    if (L.has(rh) || L.has(rw)) {
      const auto rs = L.shape(rh);
      const int64_t rel = rs.size() == 2 ? rs[0] : 0, hd = rs.size() == 2 ? rs[1] : 0;
      if (rel <= 0 || hd <= 0 || I % hd || rel % 2 == 0)
        fail(
            "{}: tensor '{}' has shape {}, expected [2 * size - 1, head_dim] with head_dim dividing the attention "
            "width {} ('{}' has shape {})",
            file, L.key(rh), shape_str(rs), I, L.key(qkv), shape_str(L.shape(qkv)));
      l.heads = int(I / hd);
      if (given_heads > 0 && l.heads != given_heads)
        fail("{}: tensor '{}' has shape {} but [{}, {}] was expected ({} heads given, attention width {})", file,
             L.key(rh), shape_str(rs), rel, I % given_heads ? std::string("?") : std::to_string(I / given_heads),
             given_heads, I);
      const int size = int(rel + 1) / 2;
      if (size > v.grid)
        fail("{}: tensor '{}' covers {} positions, more than the {}-token grid", file, L.key(rh), size, v.grid);
      l.window = size == v.grid ? 0 : size;
      l.rel_h = L.get(rh, {rel, hd});
      l.rel_w = L.get(rw, {rel, hd});
    } else {
      // No relative positions: the head count given or from config.json, the window from config.json.
      const int heads = given_heads > 0 ? given_heads : cfg.vit_heads;
      if (heads <= 0 || !cfg.has_vision)
        fail(
            "{}: layer {} has no relative-position tables ('{}'), so its head count and window need config.json's "
            "vision_config (num_attention_heads, window_size, global_attn_indexes) beside the weights",
            file, i, L.key(rh));
      if (I % heads)
        fail("{}: tensor '{}' has shape {}: attention width {} is not a multiple of {} heads", file, L.key(qkv),
             shape_str(L.shape(qkv)), I, heads);
      l.heads = heads;
      const bool global = std::find(cfg.global_layers.begin(), cfg.global_layers.end(), i) != cfg.global_layers.end();
      l.window = global || cfg.window <= 0 || cfg.window >= v.grid ? 0 : cfg.window;
    }
    l.ln1 = L.ln(p + "layer_norm1", C);
    l.ln2 = L.ln(p + "layer_norm2", C);
    const int mlp = int(L.dim(p + "mlp.lin1.weight", 0));
    l.fc1 = L.lin(p + "mlp.lin1", mlp, C);
    l.fc2 = L.lin(p + "mlp.lin2", C, mlp);
    v.layers.push_back(std::move(l));
  }
  v.heads = v.layers[0].heads;
  for (const VitLayer& l : v.layers)
    if (l.heads != v.heads) v.heads = 0;
  v.out = int(L.dim("vision_encoder.neck.conv1.weight", 0));
  const int O = v.out;
  v.neck1 = {C, O, L.get("vision_encoder.neck.conv1.weight", {O, C, 1, 1}), std::vector<float>(O, 0.f)};
  auto w2 = L.get("vision_encoder.neck.conv2.weight", {O, O, 3, 3});
  v.neck2 = {9 * O, O, std::vector<float>(w2.size()), std::vector<float>(O, 0.f)};
  for (int o = 0; o < O; ++o)
    for (int c = 0; c < O; ++c)
      for (int k = 0; k < 9; ++k) v.neck2.w[(size_t(o) * 9 + k) * O + c] = w2[(size_t(o) * O + c) * 9 + k];
  v.neck_ln1 = L.ln("vision_encoder.neck.layer_norm1", O);
  v.neck_ln2 = L.ln("vision_encoder.neck.layer_norm2", O);
}

void load_prompt(const Loader& L, const SafeTensors& st, int C, PromptEncoder& p) {
  std::string pe = "shared_image_embedding.positional_embedding";
  if (L.naming == Naming::HuggingFace && !st.has(pe) && st.has("prompt_encoder.shared_embedding.positional_embedding"))
    pe = "prompt_encoder.shared_embedding.positional_embedding";
  p.gauss = L.get(pe, {2, C / 2});
  for (int i = 0; i < 4; ++i) p.point[i] = L.vec(fmt::format("prompt_encoder.point_embed.{}.weight", i), C);
  p.not_a_point = L.vec("prompt_encoder.not_a_point_embed.weight", C);
  p.no_mask = L.vec("prompt_encoder.no_mask_embed.weight", C);
}

void load_decoder(const Loader& L, int C, MaskDecoder& d) {
  const std::string file = L.file();
  d.iou_token = L.vec("mask_decoder.iou_token.weight", C);
  d.tokens = int(L.dim("mask_decoder.mask_tokens.weight", 0));
  d.mask_tokens = L.get("mask_decoder.mask_tokens.weight", {d.tokens, C});
  const int n = L.count("mask_decoder.transformer.layers.", "layer_norm1.weight");
  if (n == 0)
    fail("{}: no mask decoder layers found ('{}')", file,
         L.key("mask_decoder.transformer.layers.0.layer_norm1.weight"));
  for (int i = 0; i < n; ++i) {
    const std::string p = fmt::format("mask_decoder.transformer.layers.{}.", i);
    TwoWayLayer l;
    l.self_attn = L.attn(p + "self_attn", C);
    l.token_to_image = L.attn(p + "cross_attn_token_to_image", C);
    l.image_to_token = L.attn(p + "cross_attn_image_to_token", C);
    l.ln1 = L.ln(p + "layer_norm1", C);
    l.ln2 = L.ln(p + "layer_norm2", C);
    l.ln3 = L.ln(p + "layer_norm3", C);
    l.ln4 = L.ln(p + "layer_norm4", C);
    const int mlp = int(L.dim(p + "mlp.lin1.weight", 0));
    l.mlp1 = L.lin(p + "mlp.lin1", mlp, C);
    l.mlp2 = L.lin(p + "mlp.lin2", C, mlp);
    d.layers.push_back(std::move(l));
  }
  d.final_attn = L.attn("mask_decoder.transformer.final_attn_token_to_image", C);
  d.ln_final = L.ln("mask_decoder.transformer.layer_norm_final_attn", C);
  if (C % 8) fail("{}: decoder width {} is not a multiple of 8", file, C);
  d.up1 = L.upconv("mask_decoder.upscale_conv1", C, C / 4);
  d.up_ln = L.ln("mask_decoder.upscale_layer_norm", C / 4);
  d.up2 = L.upconv("mask_decoder.upscale_conv2", C / 4, C / 8);
  for (int i = 0; i < d.tokens; ++i)
    d.hyper.push_back(L.mlp(fmt::format("mask_decoder.output_hypernetworks_mlps.{}", i), C, C / 8));
  d.iou_head = L.mlp("mask_decoder.iou_prediction_head", C, d.tokens);
  d.ln_eps = L.naming == Naming::HuggingFace ? 1e-6f : 1e-5f;
  d.ln_final_eps = 1e-5f;
}

}  // namespace

SamModel SamModel::load(const std::filesystem::path& path, const SamOptions& opt) {
  SafeTensors st(path);
  const std::string file = path.string();
  SamModel m;
  m.path = path;
  if (st.has("vision_encoder.pos_embed")) {
    m.naming = Naming::HuggingFace;
  } else if (st.has("image_encoder.pos_embed") || st.has("image_encoder.module.pos_embed")) {
    m.naming = Naming::SegmentAnything;
  } else {
    fail(
        "{}: not a SAM model in Hugging Face SamModel or segment-anything naming (no 'vision_encoder.pos_embed' "
        "or 'image_encoder.pos_embed')",
        file);
  }
  Loader L{st, m.naming, !st.has("image_encoder.pos_embed") && st.has("image_encoder.module.pos_embed")};
  const ConfigHints cfg = read_config(path);
  load_vision(L, cfg, opt.vit_heads, m.vision);
  const int C = m.vision.out;
  if (C % 2) fail("{}: neck width {} is odd", file, C);
  load_prompt(L, st, C, m.prompt);
  load_decoder(L, C, m.decoder);
  const int heads = opt.decoder_heads > 0 ? opt.decoder_heads : cfg.decoder_heads > 0 ? cfg.decoder_heads : 8;
  for (const TwoWayLayer& l : m.decoder.layers)
    if (l.token_to_image.q.out % heads || C % heads)
      fail("{}: {} decoder heads do not divide the attention widths ({} and {})", file, heads, C,
           l.token_to_image.q.out);
  m.decoder.heads = heads;
  m.set_precision(opt.precision);
  return m;
}

void SamModel::set_precision(nn::Precision p) {
  precision = p;
  VisionEncoder& v = vision;
  std::vector<nn::Linear*> large{&v.patch_embed, &v.neck1, &v.neck2};
  for (VitLayer& l : v.layers)
    for (nn::Linear* x : {&l.qkv, &l.proj, &l.fc1, &l.fc2}) large.push_back(x);
  // The decoder's projections of the image tokens (its few-token ones stay float32: kFewRows in nn::linear).
  MaskDecoder& d = decoder;
  auto attention = [&](Attention& a) {
    for (nn::Linear* x : {&a.q, &a.k, &a.v, &a.out}) large.push_back(x);
  };
  for (TwoWayLayer& l : d.layers) {
    attention(l.token_to_image);
    attention(l.image_to_token);
  }
  attention(d.final_attn);
  for (nn::Linear* l : large) {
    if (p == nn::Precision::BF16) nn::use_bf16(*l);
    else l->w16.clear();
  }
  for (Upconv* u : {&d.up1, &d.up2}) u->w16 = p == nn::Precision::BF16 ? nn::to_bf16(u->w) : std::vector<uint16_t>{};
}

std::string SamModel::describe() const {
  std::string windows, global, widths;
  bool uniform = true;
  for (size_t i = 0; i < vision.layers.size(); ++i) {
    const VitLayer& l = vision.layers[i];
    if (l.window == 0) global += (global.empty() ? "" : ",") + std::to_string(i);
    else if (windows.empty()) windows = std::to_string(l.window);
    const int h = l.heads > 0 ? l.heads : vision.heads;
    widths += fmt::format("{}{}x{}/{}", i ? "," : "", h, h > 0 ? l.qkv.out / 3 / h : 0, l.fc1.out);
    const VitLayer& f = vision.layers[0];
    uniform =
        uniform && h == (f.heads > 0 ? f.heads : vision.heads) && l.qkv.out == f.qkv.out && l.fc1.out == f.fc1.out;
  }
  const std::string vit =
      uniform ? fmt::format("{} heads", vision.heads) : fmt::format("per-layer heads x head dim / MLP [{}]", widths);
  return fmt::format(
             "{} naming; ViT hidden {} x {} layers, {}, patch {}, {}px, window {}, global layers [{}]; "
             "neck {}; decoder {} layers, {} heads, {} mask tokens",
             naming == Naming::HuggingFace ? "Hugging Face" : "segment-anything", vision.hidden, vision.layers.size(),
             vit, vision.patch, image_size(), windows.empty() ? "-" : windows, global, vision.out,
             decoder.layers.size(), decoder.heads, decoder.tokens) +
         (precision == nn::Precision::BF16 ? fmt::format("; bf16 products ({})", nn::bf16_kernel_name()) : "");
}

}  // namespace hgs::sam
