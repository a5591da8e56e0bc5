// A pruned SAM (SlimSAM-like: every ViT layer its own heads, head dim and MLP width, one residual width)
// against PyTorch (tests/data/sam/pruned, tools/sam_reference): every stage, in both namings, with the
// tolerances of test_model.cpp / test_amg.cpp; and the loader's one-line errors for mis-shaped per-layer tensors.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>

#include "core/error.h"
#include "nn/safetensors.h"
#include "sam/amg.h"
#include "sam_test_util.h"
#include "test_util.h"

namespace hgs::test {
namespace {

std::filesystem::path pruned_file() { return sam_data("pruned/pruned_sam.safetensors"); }
std::vector<float> pref(const std::string& name) { return sam_ref("pruned/" + name); }

const sam::SamModel& pruned_sam() {
  static const sam::SamModel m = sam::SamModel::load(pruned_file());
  return m;
}

// The same weights in segment-anything naming (renamed by the test's own table, F32).
const sam::SamModel& pruned_sam_sa() {
  static const sam::SamModel m = [] {
    static TempDir t;
    rewrite(t / "pruned_sa.safetensors", to_segment_anything, "", {}, pruned_file());
    return sam::SamModel::load(t / "pruned_sa.safetensors");
  }();
  return m;
}

sam::ImageEmbedding ref_embedding(const sam::SamModel& m, const RefPrompts& r) {
  return embedding_from(m, pref("embedding.npy"), r);
}

std::string load_error(const std::filesystem::path& p, const sam::SamOptions& opt = {}) {
  try {
    sam::SamModel::load(p, opt);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(SamPruned, SizesReadFromEachLayer) {
  for (const sam::SamModel* m : {&pruned_sam(), &pruned_sam_sa()}) {
    EXPECT_EQ(m->vision.hidden, 32);
    EXPECT_EQ(m->vision.heads, 0);  // the layers differ
    ASSERT_EQ(m->vision.layers.size(), 3u);
    const int heads[3] = {2, 4, 1}, hd[3] = {6, 5, 16}, mlp[3] = {40, 24, 72}, window[3] = {3, 0, 3};
    for (int i = 0; i < 3; ++i) {
      const sam::VitLayer& l = m->vision.layers[i];
      EXPECT_EQ(l.heads, heads[i]) << i;
      EXPECT_EQ(l.qkv.out, 3 * heads[i] * hd[i]) << i;
      EXPECT_EQ(l.qkv.in, 32) << i;
      EXPECT_EQ(l.proj.in, heads[i] * hd[i]) << i;
      EXPECT_EQ(l.proj.out, 32) << i;
      EXPECT_EQ(l.rel_h.size(), size_t(2 * (window[i] ? window[i] : 8) - 1) * hd[i]) << i;
      EXPECT_EQ(l.fc1.out, mlp[i]) << i;
      EXPECT_EQ(l.fc2.in, mlp[i]) << i;
      EXPECT_EQ(l.window, window[i]) << i;
    }
    EXPECT_EQ(m->channels(), 32);
    EXPECT_NE(m->describe().find("per-layer heads x head dim / MLP [2x6/40,4x5/24,1x16/72]"), std::string::npos)
        << m->describe();
  }
}

TEST(SamPruned, EncoderStagesMatchTorch) {
  std::vector<float> px = sam_ref("pixels.npy");
  for (const sam::SamModel* m : {&pruned_sam(), &pruned_sam_sa()}) {
    std::vector<std::vector<float>> stages;
    std::vector<float> emb = m->encode(px.data(), &stages);
    ASSERT_EQ(stages.size(), 4u);
    EXPECT_LT(max_rel_err(stages[0], pref("patch.npy")), 2e-6);
    for (int i = 0; i < 3; ++i)
      EXPECT_LT(max_rel_err(stages[i + 1], pref("layer" + std::to_string(i) + ".npy")), 1e-5) << "layer " << i;
    EXPECT_LT(max_rel_err(emb, pref("embedding.npy")), 1e-5);
  }
  // The same weights in both namings: the same encoder, bit for bit.
  EXPECT_EQ(pruned_sam().encode(px.data()), pruned_sam_sa().encode(px.data()));
}

TEST(SamPruned, EmbedFromTheImageMatchesTorch) {
  sam::ImageEmbedding e = pruned_sam().embed(sam_image());
  EXPECT_LT(max_rel_err(e.data, pref("embedding.npy")), 1e-5);
}

TEST(SamPruned, PromptsAndDensePeMatchTorch) {
  RefPrompts r = read_prompts();
  EXPECT_LT(max_rel_err(pruned_sam().dense_pe(), pref("dense_pe.npy")), 2e-6);
  EXPECT_LT(max_rel_err(pruned_sam_sa().dense_pe(), pref("dense_pe.npy")), 2e-6);
  sam::ImageEmbedding e = ref_embedding(pruned_sam(), r);
  for (size_t k = 0; k < r.prompts.size(); ++k)
    for (const sam::SamModel* m : {&pruned_sam(), &pruned_sam_sa()})
      EXPECT_LT(max_rel_err(m->encode_prompt(m->to_input(e, r.prompts[k])),
                            pref("sparse" + std::to_string(k) + ".npy")),
                2e-6)
          << "prompt " << k;
}

TEST(SamPruned, DecoderMatchesTorch) {
  RefPrompts r = read_prompts();
  sam::ImageEmbedding e = ref_embedding(pruned_sam(), r);
  for (size_t k = 0; k < r.prompts.size(); ++k) {
    sam::Prediction p = pruned_sam().predict(e, r.prompts[k]);
    EXPECT_EQ(p.size, 32);
    if (k == 1 || k == 3) {  // the low-res masks of two prompt sets keep the fixture small
      EXPECT_LT(max_rel_err(p.lowres, pref("lowres" + std::to_string(k) + ".npy")), 1e-5) << "prompt " << k;
    }
    EXPECT_LT(max_rel_err(p.iou, pref("iou" + std::to_string(k) + ".npy")), 5e-6) << "prompt " << k;
    // segment-anything naming: the two-way blocks' LayerNorm eps is 1e-5 (1e-6 in the reference), as for the
    // tiny model (SamWeights.SegmentAnythingNamingGivesTheSameModel).
    sam::Prediction q = pruned_sam_sa().predict(e, r.prompts[k]);
    EXPECT_LT(max_rel_err(q.lowres, p.lowres), 1e-4) << "prompt " << k;
    EXPECT_LT(max_rel_err(q.iou, p.iou), 1e-4) << "prompt " << k;
  }
}

TEST(SamPruned, PostProcessingAndEndToEndMatchTorch) {
  RefPrompts r = read_prompts();
  sam::ImageEmbedding ref = ref_embedding(pruned_sam(), r);
  std::vector<float> low = pref("lowres3.npy");
  EXPECT_LT(max_rel_err(pruned_sam().upscale_masks(ref, low.data(), 4), pref("masks3.npy")), 2e-6);
  sam::ImageEmbedding e = pruned_sam().embed(sam_image());
  sam::Prediction p = pruned_sam().predict(e, r.prompts[3]);
  EXPECT_LT(max_rel_err(pruned_sam().upscale_masks(e, p.lowres.data(), p.tokens), pref("masks3.npy")), 1e-5);
  EXPECT_LT(max_rel_err(p.iou, pref("iou3.npy")), 1e-5);
}

TEST(SamPruned, AutomaticMasksMatchTorch) {
  nlohmann::json j = nlohmann::json::parse(std::ifstream(sam_data("pruned/amg.json")));
  const sam::AmgOptions o = reference_amg_options(j);
  sam::ImageEmbedding e = pruned_sam().embed(sam_image());
  std::vector<sam::AmgMask> got = sam::generate_masks(pruned_sam(), e, o);
  std::vector<float> ref_masks = pref("amg_masks.npy");
  const auto& ref = j["masks"];
  ASSERT_GE(ref.size(), 2u);
  expect_amg_masks_match(got, ref, ref_masks, size_t(e.orig_h) * e.orig_w);
}

// A mis-shaped per-layer tensor of the pruned model: a one-line error naming the file, the tensor, its shape
// and (where a shape is implied) the expected one.
void expect_error(const std::string& tensor, const std::vector<int64_t>& shape, const std::vector<std::string>& parts,
                  bool segment_anything = false, const sam::SamOptions& opt = {}) {
  TempDir t;
  const std::string name = segment_anything ? to_segment_anything(tensor) : tensor;
  const std::function<std::string(const std::string&)> rename =
      segment_anything ? std::function<std::string(const std::string&)>(to_segment_anything)
                       : [](const std::string& n) { return n; };
  rewrite(t / "p.safetensors", rename, tensor, shape, pruned_file());
  std::string err = load_error(t / "p.safetensors", opt);
  EXPECT_NE(err.find("p.safetensors: tensor '" + name + "'"), std::string::npos) << err;
  for (const std::string& p : parts) EXPECT_NE(err.find(p), std::string::npos) << p << " in: " << err;
  EXPECT_EQ(err.find('\n'), std::string::npos) << err;
}

TEST(SamPruned, MisShapedLayerTensorsAreNamed) {
  // Attention output projection of layer 1: [32, 20] stored as [20, 32].
  expect_error("vision_encoder.layers.1.attn.proj.weight", {20, 32}, {"has shape [20, 32] but [32, 20] was expected"});
  expect_error("vision_encoder.layers.1.attn.proj.weight", {20, 32}, {"has shape [20, 32] but [32, 20] was expected"},
               true);
  // MLP of layer 2 (width 72): lin2 [32, 72] stored as [72, 32]; lin1's bias against lin1's rows.
  expect_error("vision_encoder.layers.2.mlp.lin2.weight", {72, 32}, {"has shape [72, 32] but [32, 72] was expected"});
  expect_error("vision_encoder.layers.0.mlp.lin1.bias", {2, 20}, {"has shape [2, 20] but [40] was expected"});
  // qkv rows not a multiple of 3: [60, 32] as [64, 30].
  expect_error("vision_encoder.layers.1.attn.qkv.weight", {64, 30}, {"[64, 30]", "3 * attention width"});
  // Relative-position table whose width does not divide the attention width (20): [15, 5] as [5, 15].
  expect_error("vision_encoder.layers.1.attn.rel_pos_h", {5, 15}, {"[5, 15]", "attention width 20"});
  // rel_pos_w disagreeing with rel_pos_h: [5, 16] as [16, 5].
  expect_error("vision_encoder.layers.2.attn.rel_pos_w", {16, 5}, {"has shape [16, 5] but [5, 16] was expected"});
}

TEST(SamPruned, GivenHeadCountIsChecked) {
  sam::SamOptions opt;
  opt.vit_heads = 2;  // layer 0 has 2 heads, layer 1 has 4 (head dim 5 of width 20)
  std::string err = load_error(pruned_file(), opt);
  EXPECT_NE(err.find("tensor 'vision_encoder.layers.1.attn.rel_pos_h' has shape [15, 5] but [15, 10] was expected"),
            std::string::npos)
      << err;
  EXPECT_EQ(err.find('\n'), std::string::npos) << err;
}

// Without relative-position tables a layer takes its head count and window from config.json (or the option);
// zero tables are the same attention, bit for bit.
TEST(SamPruned, LayerWithoutRelativePositionsUsesTheConfig) {
  TempDir t;
  const auto is_rel1 = [](const std::string& n) { return n.rfind("vision_encoder.layers.1.attn.rel_pos_", 0) == 0; };
  rewrite(
      t / "zero.safetensors", [](const std::string& n) { return n; }, "", {}, pruned_file(),
      [&](const std::string& n, std::vector<float>& v) {
        if (is_rel1(n)) std::fill(v.begin(), v.end(), 0.f);
      });
  std::filesystem::create_directories(t / "norel");
  rewrite(
      t / "norel" / "m.safetensors", [&](const std::string& n) { return is_rel1(n) ? std::string() : n; }, "", {},
      pruned_file());
  // No config: a one-line error naming the missing table.
  std::string err = load_error(t / "norel" / "m.safetensors");
  EXPECT_NE(err.find("vision_encoder.layers.1.attn.rel_pos_h"), std::string::npos) << err;
  EXPECT_EQ(err.find('\n'), std::string::npos) << err;
  // A head count that does not divide the layer's attention width (20).
  std::ofstream(t / "norel" / "config.json")
      << R"({"vision_config": {"num_attention_heads": 3, "window_size": 3, "global_attn_indexes": [1]}})";
  err = load_error(t / "norel" / "m.safetensors");
  EXPECT_NE(err.find("tensor 'vision_encoder.layers.1.attn.qkv.weight' has shape [60, 32]"), std::string::npos) << err;
  EXPECT_NE(err.find("not a multiple of 3 heads"), std::string::npos) << err;
  std::ofstream(t / "norel" / "config.json")
      << R"({"vision_config": {"num_attention_heads": 4, "window_size": 3, "global_attn_indexes": [1]}})";
  sam::SamModel a = sam::SamModel::load(t / "zero.safetensors"), b = sam::SamModel::load(t / "norel" / "m.safetensors");
  EXPECT_TRUE(b.vision.layers[1].rel_h.empty());
  EXPECT_EQ(b.vision.layers[1].heads, 4);
  EXPECT_EQ(b.vision.layers[1].window, 0);
  EXPECT_EQ(b.vision.layers[0].window, 3);
  std::vector<float> px = sam_ref("pixels.npy");
  std::vector<std::vector<float>> sa, sb;
  a.encode(px.data(), &sa);
  b.encode(px.data(), &sb);
  EXPECT_EQ(sa, sb);
  // ... and the tables do matter: the zeroed model is not the reference.
  EXPECT_GT(max_rel_err(sa[2], pref("layer1.npy")), 1e-3);
}

// SlimSAM's pruning code keeps q, k, v as separate linears ('attn.q', 'attn.k', 'attn.v', each [I, C]): the
// pruned model saved that way in segment-anything naming, optionally with one tensor given another shape.
void write_split_qkv(const std::filesystem::path& dst, const std::string& reshape_name = "",
                     const std::vector<int64_t>& new_shape = {}) {
  nn::SafeTensors st(pruned_file());
  const auto names = st.names();
  std::vector<std::vector<float>> data;
  std::vector<nn::TensorToWrite> out;
  data.reserve(3 * names.size());
  const std::regex qkv(R"((.*\.attn\.)qkv\.(weight|bias))");
  for (const std::string& n : names) {
    std::vector<float> v = st.to_float(n);
    std::vector<int64_t> shape = st.info(n).shape;
    const std::string m = to_segment_anything(n);
    std::smatch mt;
    if (std::regex_match(m, mt, qkv)) {
      const size_t part = v.size() / 3;
      shape[0] /= 3;
      for (int j = 0; j < 3; ++j) {
        data.emplace_back(v.begin() + j * part, v.begin() + (j + 1) * part);
        const std::string name = mt[1].str() + "qkv"[j] + "." + mt[2].str();
        out.push_back({name, name == reshape_name ? new_shape : shape, data.back().data()});
      }
    } else {
      data.push_back(std::move(v));
      out.push_back({m, m == reshape_name ? new_shape : shape, data.back().data()});
    }
  }
  nn::write_safetensors(dst, out, nn::StDType::F32);
}

TEST(SamPruned, SeparateQkvLinearsLoad) {
  TempDir t;
  write_split_qkv(t / "split.safetensors");
  nn::SafeTensors st(t / "split.safetensors");
  ASSERT_TRUE(st.has("image_encoder.blocks.1.attn.k.weight"));
  ASSERT_FALSE(st.has("image_encoder.blocks.1.attn.qkv.weight"));
  sam::SamModel m = sam::SamModel::load(t / "split.safetensors");
  EXPECT_EQ(m.vision.layers[1].qkv.out, 60);
  EXPECT_EQ(m.vision.layers[1].heads, 4);
  std::vector<float> px = sam_ref("pixels.npy");
  std::vector<std::vector<float>> a, b;
  EXPECT_EQ(m.encode(px.data(), &a), pruned_sam().encode(px.data(), &b));
  EXPECT_EQ(a, b);
  EXPECT_LT(max_rel_err(a[3], pref("layer2.npy")), 1e-5);
  // SlimSAM's checkpoints hold the encoder in a DataParallel wrapper: 'image_encoder.module.*' also loads.
  nn::SafeTensors sp(t / "split.safetensors");
  const auto sp_names = sp.names();
  std::vector<std::vector<float>> sp_data;
  std::vector<nn::TensorToWrite> sp_out;
  sp_data.reserve(sp_names.size());
  for (const std::string& n : sp_names) {
    sp_data.push_back(sp.to_float(n));
    std::string m2 = n;
    if (m2.rfind("image_encoder.", 0) == 0) m2.insert(14, "module.");
    sp_out.push_back({m2, sp.info(n).shape, sp_data.back().data()});
  }
  nn::write_safetensors(t / "dp.safetensors", sp_out, nn::StDType::F32);
  sam::SamModel dp = sam::SamModel::load(t / "dp.safetensors");
  EXPECT_EQ(dp.encode(px.data()), m.encode(px.data()));
  EXPECT_EQ(dp.naming, sam::Naming::SegmentAnything);
  // A mis-shaped k of layer 2 ([16, 32] stored as [32, 16]) is named.
  write_split_qkv(t / "bad.safetensors", "image_encoder.blocks.2.attn.k.weight", {32, 16});
  std::string err = load_error(t / "bad.safetensors");
  EXPECT_NE(err.find("bad.safetensors: tensor 'image_encoder.blocks.2.attn.k.weight' has shape [32, 16] but [16, 32] "
                     "was expected"),
            std::string::npos)
      << err;
  EXPECT_EQ(err.find('\n'), std::string::npos) << err;
}

}  // namespace
}  // namespace hgs::test
