// Loading a CLIP model from safetensors: detects the naming scheme, infers widths, depths, patch size, grid,
// context and embedding size from tensor shapes, converts everything to float32 in one canonical layout
// (Linear weights [out, in], fused qkv, projections [width, D]) and checks every shape.
#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "clip/model.h"
#include "core/error.h"
#include "core/json_file.h"
#include "nn/safetensors.h"
#include "nn/transformer.h"

namespace hgs::clip {
namespace {
namespace fs = std::filesystem;

struct ConfigHints {
  int vision_heads = 0, text_heads = 0;
  std::optional<Activation> act;
};

std::optional<Activation> parse_act(const std::string& s, const fs::path& file) {
  if (s == "gelu") return Activation::GELU;
  if (s == "quick_gelu") return Activation::QuickGELU;
  fail("{}: unsupported hidden_act \"{}\" (gelu or quick_gelu)", file.string(), s);
}

// Reads config.json (HF) or open_clip_config.json beside the weights, when present.
ConfigHints read_config(const fs::path& weights) {
  ConfigHints h;
  fs::path dir = weights.parent_path();
  if (dir.empty()) dir = ".";
  try {
    fs::path hf = dir / "config.json";
    if (fs::is_regular_file(hf)) {
      nlohmann::json j = read_json_file(hf);
      if (j.contains("vision_config")) {
        auto& v = j["vision_config"];
        if (v.contains("num_attention_heads")) h.vision_heads = v["num_attention_heads"].get<int>();
        if (v.contains("hidden_act")) h.act = parse_act(v["hidden_act"].get<std::string>(), hf);
      }
      if (j.contains("text_config")) {
        auto& t = j["text_config"];
        if (t.contains("num_attention_heads")) h.text_heads = t["num_attention_heads"].get<int>();
      }
    }
    fs::path oc = dir / "open_clip_config.json";
    if (fs::is_regular_file(oc)) {
      nlohmann::json j = read_json_file(oc);
      auto& m = j.contains("model_cfg") ? j["model_cfg"] : j;
      if (m.contains("quick_gelu")) h.act = m["quick_gelu"].get<bool>() ? Activation::QuickGELU : Activation::GELU;
      if (m.contains("text_cfg") && m["text_cfg"].contains("heads")) h.text_heads = m["text_cfg"]["heads"].get<int>();
      if (m.contains("vision_cfg")) {
        auto& v = m["vision_cfg"];
        int width = v.value("width", 0), hw = v.value("head_width", 64);
        if (width > 0 && hw > 0) h.vision_heads = width / hw;
      }
    }
  } catch (const nlohmann::json::exception& e) {
    fail("{}: cannot read the model config beside the weights ({})", dir.string(), e.what());
  }
  return h;
}

struct Loader {
  const nn::SafeTensors& st;
  std::string file() const { return st.path().string(); }

  std::vector<float> get(const std::string& name, const std::vector<int64_t>& shape) {
    return st.to_float(name, shape);
  }
  int64_t dim(const std::string& name, int i) {
    const auto& t = st.info(name);
    if (int(t.shape.size()) <= i)
      fail("{}: tensor '{}' has shape {}, too few dimensions", file(), name, nn::shape_str(t.shape));
    return t.shape[i];
  }
  LayerNorm ln(const std::string& prefix, int w) { return {get(prefix + ".weight", {w}), get(prefix + ".bias", {w})}; }
  Linear lin(const std::string& prefix, int out, int in) {
    return {in, out, get(prefix + ".weight", {out, in}), get(prefix + ".bias", {out})};
  }
  int count_layers(const std::string& prefix, const std::string& probe) {
    int n = 0;
    while (st.has(fmt::format("{}{}.{}", prefix, n, probe))) ++n;
    if (n == 0) fail("{}: no transformer layers found under '{}N'", file(), prefix);
    return n;
  }
  // Transposes a [rows, cols] matrix.
  static std::vector<float> transpose(const std::vector<float>& a, int rows, int cols) {
    std::vector<float> t(a.size());
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j) t[size_t(j) * rows + i] = a[size_t(i) * cols + j];
    return t;
  }

  Transformer openclip_tr(const std::string& prefix, int w, int heads) {
    Transformer tr;
    tr.width = w;
    tr.heads = heads;
    int L = count_layers(prefix, "ln_1.weight");
    for (int i = 0; i < L; ++i) {
      std::string p = fmt::format("{}{}.", prefix, i);
      Block b;
      b.ln1 = ln(p + "ln_1", w);
      b.ln2 = ln(p + "ln_2", w);
      b.qkv = {w, 3 * w, get(p + "attn.in_proj_weight", {3 * w, w}), get(p + "attn.in_proj_bias", {3 * w})};
      b.out = lin(p + "attn.out_proj", w, w);
      int mlp = int(dim(p + "mlp.c_fc.weight", 0));
      b.fc = lin(p + "mlp.c_fc", mlp, w);
      b.proj = lin(p + "mlp.c_proj", w, mlp);
      tr.blocks.push_back(std::move(b));
    }
    return tr;
  }

  Transformer hf_tr(const std::string& prefix, int w, int heads) {
    Transformer tr;
    tr.width = w;
    tr.heads = heads;
    int L = count_layers(prefix, "layer_norm1.weight");
    for (int i = 0; i < L; ++i) {
      std::string p = fmt::format("{}{}.", prefix, i);
      Block b;
      b.ln1 = ln(p + "layer_norm1", w);
      b.ln2 = ln(p + "layer_norm2", w);
      b.qkv.in = w;
      b.qkv.out = 3 * w;
      for (const char* n : {"q_proj", "k_proj", "v_proj"}) {
        auto wt = get(p + "self_attn." + n + ".weight", {w, w});
        auto bs = get(p + "self_attn." + n + ".bias", {w});
        b.qkv.w.insert(b.qkv.w.end(), wt.begin(), wt.end());
        b.qkv.b.insert(b.qkv.b.end(), bs.begin(), bs.end());
      }
      b.out = lin(p + "self_attn.out_proj", w, w);
      int mlp = int(dim(p + "mlp.fc1.weight", 0));
      b.fc = lin(p + "mlp.fc1", mlp, w);
      b.proj = lin(p + "mlp.fc2", w, mlp);
      tr.blocks.push_back(std::move(b));
    }
    return tr;
  }
};

int heads_for(int width, int requested, const std::string& file, const char* tower) {
  int h = requested > 0 ? requested : width / 64;
  if (h <= 0 || width % h) fail("{}: {} width {} is not divisible by {} attention heads", file, tower, width, h);
  return h;
}

int grid_from_positions(int64_t n_pos, const std::string& file, const std::string& name) {
  int g = 0;
  while (int64_t(g + 1) * (g + 1) + 1 <= n_pos) ++g;
  if (int64_t(g) * g + 1 != n_pos)
    fail("{}: tensor '{}' has {} positions, not a square grid plus a class token", file, name, n_pos);
  return g;
}

}  // namespace

std::optional<Activation> parse_activation(const std::string& s) {
  if (s.empty() || s == "auto") return std::nullopt;
  if (s == "gelu") return Activation::GELU;
  if (s == "quick_gelu" || s == "quickgelu") return Activation::QuickGELU;
  fail("--act: unknown activation \"{}\" (auto, gelu or quick_gelu)", s);
}

ClipModel ClipModel::load(const std::filesystem::path& path, const ClipOptions& opt) {
  nn::SafeTensors st(path);
  Loader L{st};
  const std::string file = path.string();
  ConfigHints cfg = read_config(path);
  ClipModel m;
  m.path = path;
  if (st.has("visual.conv1.weight") || st.has("token_embedding.weight")) {
    m.naming = Naming::OpenClip;
  } else if (st.has("vision_model.embeddings.patch_embedding.weight") ||
             st.has("text_model.embeddings.token_embedding.weight")) {
    m.naming = Naming::HuggingFace;
  } else {
    fail(
        "{}: not a CLIP model in open_clip or Hugging Face CLIPModel naming (no 'visual.conv1.weight' or "
        "'vision_model.embeddings.patch_embedding.weight')",
        file);
  }
  const bool oc = m.naming == Naming::OpenClip;
  m.act = opt.activation ? *opt.activation : cfg.act ? *cfg.act : oc ? Activation::GELU : Activation::QuickGELU;
  const int vh_req = opt.vision_heads ? opt.vision_heads : cfg.vision_heads;
  const int th_req = opt.text_heads ? opt.text_heads : cfg.text_heads;

  // ---- vision ----
  const std::string conv = oc ? "visual.conv1.weight" : "vision_model.embeddings.patch_embedding.weight";
  if (st.has(conv)) {
    VisionTower& v = m.vision;
    const auto& ci = st.info(conv);
    if (ci.shape.size() != 4 || ci.shape[1] != 3 || ci.shape[2] != ci.shape[3])
      fail("{}: tensor '{}' has shape {}, expected [width, 3, patch, patch]", file, conv, nn::shape_str(ci.shape));
    const int w = int(ci.shape[0]);
    v.patch = int(ci.shape[2]);
    v.patch_embed = {3 * v.patch * v.patch, w, L.get(conv, {w, 3, v.patch, v.patch}), std::vector<float>(w, 0.f)};
    const std::string pos = oc ? "visual.positional_embedding" : "vision_model.embeddings.position_embedding.weight";
    v.grid = grid_from_positions(L.dim(pos, 0), file, pos);
    v.pos = L.get(pos, {int64_t(v.grid) * v.grid + 1, w});
    v.cls = L.get(oc ? "visual.class_embedding" : "vision_model.embeddings.class_embedding", {w});
    v.ln_pre = L.ln(oc ? "visual.ln_pre" : "vision_model.pre_layrnorm", w);
    v.ln_post = L.ln(oc ? "visual.ln_post" : "vision_model.post_layernorm", w);
    const int heads = heads_for(w, vh_req, file, "vision");
    v.tr = oc ? L.openclip_tr("visual.transformer.resblocks.", w, heads)
              : L.hf_tr("vision_model.encoder.layers.", w, heads);
    const Linear& qkv = v.tr.blocks.back().qkv;
    v.last_value = {w, w, std::vector<float>(qkv.w.begin() + size_t(2) * w * w, qkv.w.end()),
                    std::vector<float>(qkv.b.begin() + 2 * w, qkv.b.end())};
    if (oc) {
      m.embed_dim = int(L.dim("visual.proj", 1));
      v.proj = L.get("visual.proj", {w, m.embed_dim});
    } else {
      m.embed_dim = int(L.dim("visual_projection.weight", 0));
      v.proj = Loader::transpose(L.get("visual_projection.weight", {m.embed_dim, w}), m.embed_dim, w);
    }
    m.has_vision = true;
  }
  // ---- text ----
  const std::string tok = oc ? "token_embedding.weight" : "text_model.embeddings.token_embedding.weight";
  if (st.has(tok)) {
    TextTower& t = m.text;
    const int w = int(L.dim(tok, 1));
    t.vocab = int(L.dim(tok, 0));
    t.tok_emb = L.get(tok, {t.vocab, w});
    const std::string pos = oc ? "positional_embedding" : "text_model.embeddings.position_embedding.weight";
    t.context = int(L.dim(pos, 0));
    t.pos = L.get(pos, {t.context, w});
    t.ln_final = L.ln(oc ? "ln_final" : "text_model.final_layer_norm", w);
    const int heads = heads_for(w, th_req, file, "text");
    t.tr = oc ? L.openclip_tr("transformer.resblocks.", w, heads) : L.hf_tr("text_model.encoder.layers.", w, heads);
    int d;
    if (oc) {
      d = int(L.dim("text_projection", 1));
      t.proj = L.get("text_projection", {w, d});
    } else {
      d = int(L.dim("text_projection.weight", 0));
      t.proj = Loader::transpose(L.get("text_projection.weight", {d, w}), d, w);
    }
    if (m.has_vision && d != m.embed_dim)
      fail("{}: text projection gives {} dimensions but the image projection {}", file, d, m.embed_dim);
    m.embed_dim = d;
    m.has_text = true;
  }
  if (!m.has_vision && !m.has_text) fail("{}: neither a vision nor a text tower was found", file);
  return m;
}

void ClipModel::set_precision(Precision p) {
  precision = p;
  std::vector<Linear*> ls{&vision.patch_embed, &vision.last_value};
  for (Block& b : vision.tr.blocks)
    for (Linear* l : {&b.qkv, &b.out, &b.fc, &b.proj}) ls.push_back(l);
  for (Linear* l : ls) {
    if (p == Precision::BF16 && !l->w.empty()) nn::use_bf16(*l);
    else l->w16.clear();
  }
}

std::string ClipModel::describe() const {
  std::string s = fmt::format("{} naming, D = {}, {}", naming == Naming::OpenClip ? "open_clip" : "Hugging Face",
                              embed_dim, act == Activation::GELU ? "GELU" : "QuickGELU");
  if (has_vision)
    s += fmt::format("; vision ViT width {} x {} layers, {} heads, patch {}, {}px", vision.tr.width,
                     vision.tr.blocks.size(), vision.tr.heads, vision.patch, image_size());
  if (has_text)
    s += fmt::format("; text width {} x {} layers, {} heads, context {}, vocab {}", text.tr.width,
                     text.tr.blocks.size(), text.tr.heads, text.context, text.vocab);
  if (precision == Precision::BF16) s += fmt::format("; vision linear layers in bf16 ({})", nn::bf16_kernel_name());
  return s;
}

}  // namespace hgs::clip
