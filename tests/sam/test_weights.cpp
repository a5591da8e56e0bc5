// SAM weight files: segment-anything naming gives the same model, and a file that does not match is a one-line
// error naming the tensor.
#include <gtest/gtest.h>

#include <functional>
#include <regex>

#include "clip/safetensors.h"
#include "core/error.h"
#include "sam_test_util.h"
#include "test_util.h"

namespace hgs::test {
namespace {

// Copies the tiny model to `dst`, renaming tensors with `rename` (empty result = drop) and optionally giving
// one tensor another shape (same element count).
void rewrite(const std::filesystem::path& dst, const std::function<std::string(const std::string&)>& rename,
             const std::string& reshape_name = "", const std::vector<int64_t>& new_shape = {}) {
  clip::SafeTensors st(sam_data("tiny_sam.safetensors"));
  std::vector<std::vector<float>> data;
  std::vector<clip::TensorToWrite> out;
  const auto names = st.names();
  data.reserve(names.size());
  for (const std::string& n : names) {
    std::string m = rename(n);
    if (m.empty()) continue;
    data.push_back(st.to_float(n));
    std::vector<int64_t> shape = st.info(n).shape;
    if (n == reshape_name) shape = new_shape;
    out.push_back({m, shape, data.back().data()});
  }
  clip::write_safetensors(dst, out, clip::StDType::F32);
}

std::string sub(std::string s, const std::string& re, const std::string& by) { return std::regex_replace(s, std::regex(re), by); }

// segment-anything's state-dict names for the tiny model's tensors (written independently of src/sam/load.cpp).
std::string to_segment_anything(const std::string& n) {
  std::string s = n;
  s = sub(s, R"(^shared_image_embedding\.positional_embedding$)", "prompt_encoder.pe_layer.positional_encoding_gaussian_matrix");
  s = sub(s, R"(^vision_encoder\.patch_embed\.projection)", "image_encoder.patch_embed.proj");
  s = sub(s, R"(^vision_encoder\.layers\.(\d+)\.layer_norm(\d))", "image_encoder.blocks.$1.norm$2");
  s = sub(s, R"(^vision_encoder\.layers\.)", "image_encoder.blocks.");
  s = sub(s, R"(^vision_encoder\.neck\.conv1)", "image_encoder.neck.0");
  s = sub(s, R"(^vision_encoder\.neck\.layer_norm1)", "image_encoder.neck.1");
  s = sub(s, R"(^vision_encoder\.neck\.conv2)", "image_encoder.neck.2");
  s = sub(s, R"(^vision_encoder\.neck\.layer_norm2)", "image_encoder.neck.3");
  s = sub(s, R"(^vision_encoder\.)", "image_encoder.");
  s = sub(s, R"(^prompt_encoder\.point_embed\.)", "prompt_encoder.point_embeddings.");
  s = sub(s, R"(transformer\.layers\.(\d+)\.layer_norm(\d))", "transformer.layers.$1.norm$2");
  s = sub(s, R"(layer_norm_final_attn)", "norm_final_attn");
  s = sub(s, R"(upscale_conv1)", "output_upscaling.0");
  s = sub(s, R"(upscale_layer_norm)", "output_upscaling.1");
  s = sub(s, R"(upscale_conv2)", "output_upscaling.3");
  // MLP heads of 3 layers: proj_in, layers.0, proj_out -> layers.0, 1, 2.
  s = sub(s, R"((mlps\.\d+|iou_prediction_head)\.layers\.0\.)", "$1.layers.1.");
  s = sub(s, R"((mlps\.\d+|iou_prediction_head)\.proj_in\.)", "$1.layers.0.");
  s = sub(s, R"((mlps\.\d+|iou_prediction_head)\.proj_out\.)", "$1.layers.2.");
  return s;
}

std::string load_error(const std::filesystem::path& p) {
  try {
    sam::SamModel::load(p);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(SamWeights, SegmentAnythingNamingGivesTheSameModel) {
  TempDir t;
  rewrite(t / "sa.safetensors", to_segment_anything);
  sam::SamModel m = sam::SamModel::load(t / "sa.safetensors");
  EXPECT_EQ(m.naming, sam::Naming::SegmentAnything);
  EXPECT_EQ(m.describe().substr(0, 16), "segment-anything");
  const sam::SamModel& hf = tiny_sam();
  // Same weights: the encoder is bit-identical.
  std::vector<float> px = sam_ref("pixels.npy");
  EXPECT_EQ(m.encode(px.data()), hf.encode(px.data()));
  EXPECT_EQ(m.dense_pe(), hf.dense_pe());
  // The decoder differs only by the two-way blocks' LayerNorm eps (1e-5 in segment-anything, 1e-6 in
  // transformers).
  EXPECT_EQ(m.decoder.ln_eps, 1e-5f);
  EXPECT_EQ(hf.decoder.ln_eps, 1e-6f);
  sam::ImageEmbedding e = hf.embed(sam_image());
  sam::Prompt p;
  p.points = {{30.f, 20.f}};
  p.labels = {1};
  sam::Prediction a = m.predict(e, p), b = hf.predict(e, p);
  EXPECT_LT(max_rel_err(a.lowres, b.lowres), 1e-4);
  EXPECT_GT(max_rel_err(a.lowres, b.lowres), 0.0);
}

TEST(SamWeights, MissingTensorIsNamed) {
  TempDir t;
  const std::string gone = "mask_decoder.transformer.layers.1.layer_norm3.bias";
  rewrite(t / "m.safetensors", [&](const std::string& n) { return n == gone ? std::string() : n; });
  std::string err = load_error(t / "m.safetensors");
  EXPECT_NE(err.find(gone), std::string::npos) << err;
  EXPECT_NE(err.find("m.safetensors"), std::string::npos) << err;
  EXPECT_EQ(err.find('\n'), std::string::npos) << err;
}

TEST(SamWeights, MisShapedTensorIsNamed) {
  TempDir t;
  const std::string bad = "vision_encoder.layers.2.mlp.lin2.weight";  // [32, 96] stored as [96, 32]
  rewrite(t / "m.safetensors", [](const std::string& n) { return n; }, bad, {96, 32});
  std::string err = load_error(t / "m.safetensors");
  EXPECT_NE(err.find(bad), std::string::npos) << err;
  EXPECT_NE(err.find("[96, 32]"), std::string::npos) << err;
}

TEST(SamWeights, BadRelativePositionsAreNamed) {
  TempDir t;
  const std::string bad = "vision_encoder.layers.0.attn.rel_pos_h";  // [5, 16] -> [16, 5]: even length
  rewrite(t / "m.safetensors", [](const std::string& n) { return n; }, bad, {16, 5});
  std::string err = load_error(t / "m.safetensors");
  EXPECT_NE(err.find(bad), std::string::npos) << err;
}

TEST(SamWeights, NotASamFile) {
  TempDir t;
  rewrite(t / "m.safetensors", [](const std::string& n) { return n.rfind("mask_decoder.", 0) == 0 ? n : std::string(); });
  std::string err = load_error(t / "m.safetensors");
  EXPECT_NE(err.find("not a SAM model"), std::string::npos) << err;
  EXPECT_NE(load_error(t / "absent.safetensors").find("absent.safetensors"), std::string::npos);
}

}  // namespace
}  // namespace hgs::test
