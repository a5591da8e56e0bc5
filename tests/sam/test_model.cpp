// The native SAM against PyTorch (tests/data/sam, tools/sam_reference): every stage of the tiny random model.
// Tolerances are relative to 1 + |ref|; observed (g++ 12, OpenBLAS 0.3.21): preprocessing 3e-7, encoder
// stages 1e-6 to 4e-6, prompts 9e-7, decoder masks 1e-6 to 4e-6, IoU 7e-7, post-processing 3.2e-7.
#include <gtest/gtest.h>

#include "sam_test_util.h"

namespace hgs::test {
namespace {

using sam::Prompt;

// The reference geometry without running the encoder (embedding from the fixture).
sam::ImageEmbedding ref_embedding(const RefPrompts& r) {
  return embedding_from(tiny_sam(), sam_ref("embedding.npy"), r);
}

TEST(SamModel, SizesReadFromTensors) {
  const sam::SamModel& m = tiny_sam();
  EXPECT_EQ(m.naming, sam::Naming::HuggingFace);
  EXPECT_EQ(m.vision.hidden, 32);
  EXPECT_EQ(m.vision.heads, 2);
  EXPECT_EQ(m.vision.patch, 8);
  EXPECT_EQ(m.image_size(), 64);
  ASSERT_EQ(m.vision.layers.size(), 3u);
  EXPECT_EQ(m.vision.layers[0].window, 3);
  EXPECT_EQ(m.vision.layers[1].window, 0);  // global
  EXPECT_EQ(m.vision.layers[2].window, 3);
  EXPECT_EQ(m.channels(), 32);
  EXPECT_EQ(m.decoder.layers.size(), 2u);
  EXPECT_EQ(m.decoder.heads, 8);
  EXPECT_EQ(m.decoder.tokens, 4);
  EXPECT_EQ(m.decoder.iou_head.layers.size(), 3u);
  EXPECT_EQ(m.decoder.iou_head.layers[0].out, 24);
  EXPECT_NE(m.describe().find("global layers [1]"), std::string::npos) << m.describe();
}

TEST(SamModel, PreprocessingMatchesTorch) {
  int h = 0, w = 0;
  std::vector<float> x = tiny_sam().preprocess(sam_image(), &h, &w);
  RefPrompts r = read_prompts();
  EXPECT_EQ(h, r.in_h);
  EXPECT_EQ(w, r.in_w);
  EXPECT_LT(max_rel_err(x, sam_ref("pixels.npy")), 2e-6);
}

TEST(SamModel, EncoderStagesMatchTorch) {
  std::vector<std::vector<float>> stages;
  std::vector<float> px = sam_ref("pixels.npy");
  std::vector<float> emb = tiny_sam().encode(px.data(), &stages);
  ASSERT_EQ(stages.size(), 4u);
  EXPECT_LT(max_rel_err(stages[0], sam_ref("patch.npy")), 2e-6);
  for (int i = 0; i < 3; ++i)
    EXPECT_LT(max_rel_err(stages[i + 1], sam_ref("layer" + std::to_string(i) + ".npy")), 1e-5) << "layer " << i;
  EXPECT_LT(max_rel_err(emb, sam_ref("embedding.npy")), 1e-5);
}

TEST(SamModel, EmbedRunsPreprocessingAndEncoder) {
  sam::ImageEmbedding e = tiny_sam().embed(sam_image());
  RefPrompts r = read_prompts();
  EXPECT_EQ(e.orig_h, r.H);
  EXPECT_EQ(e.orig_w, r.W);
  EXPECT_EQ(e.input_h, r.in_h);
  EXPECT_LT(max_rel_err(e.data, sam_ref("embedding.npy")), 1e-5);  // observed 4.8e-6 (float32 rounding)
}

TEST(SamModel, DensePositionalEncodingMatchesTorch) {
  EXPECT_LT(max_rel_err(tiny_sam().dense_pe(), sam_ref("dense_pe.npy")), 2e-6);
}

TEST(SamModel, PromptEncodingMatchesTorch) {
  RefPrompts r = read_prompts();
  sam::ImageEmbedding e = ref_embedding(r);
  for (size_t k = 0; k < r.prompts.size(); ++k) {
    std::vector<size_t> shape;
    std::vector<float> ref = sam_ref("sparse" + std::to_string(k) + ".npy", &shape);
    std::vector<float> got = tiny_sam().encode_prompt(tiny_sam().to_input(e, r.prompts[k]));
    EXPECT_LT(max_rel_err(got, ref), 2e-6) << "prompt " << k;
  }
}

TEST(SamModel, DecoderMatchesTorch) {
  RefPrompts r = read_prompts();
  sam::ImageEmbedding e = ref_embedding(r);
  for (size_t k = 0; k < r.prompts.size(); ++k) {
    sam::Prediction p = tiny_sam().predict(e, r.prompts[k]);
    EXPECT_EQ(p.size, 32);
    EXPECT_LT(max_rel_err(p.lowres, sam_ref("lowres" + std::to_string(k) + ".npy")), 1e-5) << "prompt " << k;
    EXPECT_LT(max_rel_err(p.iou, sam_ref("iou" + std::to_string(k) + ".npy")), 5e-6) << "prompt " << k;
  }
}

TEST(SamModel, PostProcessingMatchesTorch) {
  RefPrompts r = read_prompts();
  sam::ImageEmbedding e = ref_embedding(r);
  for (int k : {3}) {
    std::vector<float> low = sam_ref("lowres" + std::to_string(k) + ".npy");
    std::vector<float> full = tiny_sam().upscale_masks(e, low.data(), 4);
    EXPECT_LT(max_rel_err(full, sam_ref("masks" + std::to_string(k) + ".npy")), 2e-6) << "prompt " << k;
  }
}

TEST(SamModel, EndToEndFromTheImage) {
  RefPrompts r = read_prompts();
  sam::ImageEmbedding e = tiny_sam().embed(sam_image());
  sam::Prediction p = tiny_sam().predict(e, r.prompts[3]);
  std::vector<float> full = tiny_sam().upscale_masks(e, p.lowres.data(), p.tokens);
  EXPECT_LT(max_rel_err(full, sam_ref("masks3.npy")), 1e-5);
  EXPECT_LT(max_rel_err(p.iou, sam_ref("iou3.npy")), 1e-5);
}

TEST(SamModel, BatchedDecodeEqualsOneByOne) {
  RefPrompts r = read_prompts();
  sam::ImageEmbedding e = ref_embedding(r);
  const sam::SamModel& m = tiny_sam();
  // Prompts 0 and 2 both have 2 tokens (a point + padding, two box corners).
  std::vector<float> a = m.encode_prompt(m.to_input(e, r.prompts[0])), b = m.encode_prompt(m.to_input(e, r.prompts[2]));
  ASSERT_EQ(a.size(), b.size());
  std::vector<float> both = a;
  both.insert(both.end(), b.begin(), b.end());
  std::vector<sam::Prediction> res = m.decode(e.data.data(), both.data(), 2, int(a.size()) / m.channels());
  ASSERT_EQ(res.size(), 2u);
  EXPECT_LT(max_rel_err(res[0].lowres, sam_ref("lowres0.npy")), 1e-5);
  EXPECT_LT(max_rel_err(res[1].lowres, sam_ref("lowres2.npy")), 1e-5);
}

TEST(SamModel, DecoderHeadsMatter) {
  sam::SamOptions opt;
  opt.decoder_heads = 4;
  sam::SamModel m = sam::SamModel::load(sam_data("tiny_sam.safetensors"), opt);
  EXPECT_EQ(m.decoder.heads, 4);
  RefPrompts r = read_prompts();
  sam::Prediction p = m.predict(ref_embedding(r), r.prompts[0]);
  EXPECT_GT(max_rel_err(p.lowres, sam_ref("lowres0.npy")), 1e-3);
}

}  // namespace
}  // namespace hgs::test
