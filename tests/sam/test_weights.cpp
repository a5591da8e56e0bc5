// SAM weight files: segment-anything naming gives the same model, and a file that does not match is a one-line
// error naming the tensor.
#include <gtest/gtest.h>

#include "core/error.h"
#include "sam_test_util.h"
#include "test_util.h"

namespace hgs::test {
namespace {

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
  rewrite(t / "m.safetensors",
          [](const std::string& n) { return n.rfind("mask_decoder.", 0) == 0 ? n : std::string(); });
  std::string err = load_error(t / "m.safetensors");
  EXPECT_NE(err.find("not a SAM model"), std::string::npos) << err;
  EXPECT_NE(load_error(t / "absent.safetensors").find("absent.safetensors"), std::string::npos);
}

}  // namespace
}  // namespace hgs::test
