// Helpers shared by the SAM tests: the tiny model and reference arrays of tests/data/sam (written by
// tools/sam_reference/make_reference.py with PyTorch) and comparisons.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/npy.h"
#include "nn/safetensors.h"
#include "sam/amg.h"
#include "sam/model.h"

namespace hgs::test {

inline std::filesystem::path sam_data(const std::string& rel) {
  return std::filesystem::path(HGS_TEST_DATA) / "sam" / rel;
}

inline std::vector<float> sam_ref(const std::string& rel, std::vector<size_t>* shape = nullptr) {
  NpyArray a = read_npy(sam_data(rel));
  if (shape) *shape = a.shape;
  return a.to_float();
}

// The fixture image: uint8 [H, W, 3] / 255.
inline Image sam_image() {
  NpyArray a = read_npy(sam_data("image.npy"));
  Image img(int(a.shape[1]), int(a.shape[0]), 3);
  const uint8_t* p = a.as<uint8_t>();
  for (size_t i = 0; i < img.px.size(); ++i) img.px[i] = float(p[i]) / 255.f;
  return img;
}

inline const sam::SamModel& tiny_sam() {
  static const sam::SamModel m = sam::SamModel::load(sam_data("tiny_sam.safetensors"));
  return m;
}

// The automatic mask generator's options of a reference file (amg.json: "options").
inline sam::AmgOptions reference_amg_options(const nlohmann::json& j) {
  const auto& jo = j["options"];
  sam::AmgOptions o;
  o.points_per_side = jo["points_per_side"];
  o.points_per_batch = jo["points_per_batch"];
  o.pred_iou_thresh = jo["pred_iou_thresh"];
  o.stability_score_thresh = jo["stability_thresh"];
  o.stability_score_offset = jo["offset"];
  o.box_nms_thresh = jo["box_nms_thresh"];
  return o;
}

// The prompt sets of the reference (prompts.json): image and input sizes, prompts in original pixels.
struct RefPrompts {
  int H = 0, W = 0, in_h = 0, in_w = 0;
  std::vector<sam::Prompt> prompts;
};

inline RefPrompts read_prompts() {
  nlohmann::json j = nlohmann::json::parse(std::ifstream(sam_data("prompts.json")));
  RefPrompts r;
  r.H = j["image_hw"][0];
  r.W = j["image_hw"][1];
  r.in_h = j["input_hw"][0];
  r.in_w = j["input_hw"][1];
  for (const auto& p : j["prompts"]) {
    sam::Prompt q;
    if (p.contains("points"))
      for (size_t i = 0; i < p["points"].size(); ++i) {
        q.points.push_back({p["points"][i][0].get<float>(), p["points"][i][1].get<float>()});
        q.labels.push_back(p["labels"][i].get<int>());
      }
    if (p.contains("boxes"))
      for (const auto& b : p["boxes"])
        q.boxes.push_back({b[0].get<float>(), b[1].get<float>(), b[2].get<float>(), b[3].get<float>()});
    r.prompts.push_back(q);
  }
  return r;
}

// Largest |a - b| / (1 + |b|) over all elements; sizes must agree.
inline double max_rel_err(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double m = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    m = std::max(m, std::fabs(double(a[i]) - b[i]) / (1 + std::fabs(b[i])));
  return m;
}

// Copies a model (default the tiny one) to `dst` as F32, renaming tensors with `rename` (empty result = drop),
// optionally giving one tensor another shape (same element count) and editing values with `edit`.
inline void rewrite(const std::filesystem::path& dst, const std::function<std::string(const std::string&)>& rename,
                    const std::string& reshape_name = "", const std::vector<int64_t>& new_shape = {},
                    const std::filesystem::path& src = sam_data("tiny_sam.safetensors"),
                    const std::function<void(const std::string&, std::vector<float>&)>& edit = {}) {
  nn::SafeTensors st(src);
  std::vector<std::vector<float>> data;
  std::vector<nn::TensorToWrite> out;
  const auto names = st.names();
  data.reserve(names.size());
  for (const std::string& n : names) {
    std::string m = rename(n);
    if (m.empty()) continue;
    data.push_back(st.to_float(n));
    if (edit) edit(n, data.back());
    std::vector<int64_t> shape = st.info(n).shape;
    if (n == reshape_name) shape = new_shape;
    out.push_back({m, shape, data.back().data()});
  }
  nn::write_safetensors(dst, out, nn::StDType::F32);
}

inline std::string sub(std::string s, const std::string& re, const std::string& by) {
  return std::regex_replace(s, std::regex(re), by);
}

// segment-anything's state-dict names for the tiny model's tensors (written independently of src/sam/load.cpp).
inline std::string to_segment_anything(const std::string& n) {
  std::string s = n;
  s = sub(s, R"(^shared_image_embedding\.positional_embedding$)",
          "prompt_encoder.pe_layer.positional_encoding_gaussian_matrix");
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

// An embedding of the reference geometry from a fixture array (no encoder run).
inline sam::ImageEmbedding embedding_from(const sam::SamModel& m, std::vector<float> data, const RefPrompts& r) {
  sam::ImageEmbedding e;
  e.grid = m.vision.grid;
  e.channels = m.channels();
  e.data = std::move(data);
  e.orig_h = r.H;
  e.orig_w = r.W;
  e.input_h = r.in_h;
  e.input_w = r.in_w;
  return e;
}

// The automatic masks `got` against the reference's (JSON records `ref` and their masks [K, H, W]).
inline void expect_amg_masks_match(const std::vector<sam::AmgMask>& got, const nlohmann::json& ref,
                                   const std::vector<float>& ref_masks, size_t plane) {
  ASSERT_EQ(got.size(), ref.size());
  for (size_t k = 0; k < got.size(); ++k) {
    EXPECT_NEAR(got[k].predicted_iou, ref[k]["predicted_iou"].get<double>(), 1e-5) << k;
    EXPECT_NEAR(got[k].stability_score, ref[k]["stability_score"].get<double>(), 1e-3) << k;
    EXPECT_NEAR(got[k].point[0], ref[k]["point_coords"][0][0].get<double>(), 1e-4) << k;
    EXPECT_NEAR(got[k].point[1], ref[k]["point_coords"][0][1].get<double>(), 1e-4) << k;
    for (int c = 0; c < 4; ++c) EXPECT_EQ(got[k].bbox[c], ref[k]["bbox"][c].get<int>()) << k;
    EXPECT_EQ(got[k].area, ref[k]["area"].get<int>()) << k;
    size_t diff = 0;
    for (size_t i = 0; i < plane; ++i) diff += got[k].mask[i] != (ref_masks[k * plane + i] > 0.5f);
    EXPECT_EQ(diff, 0u) << k;
  }
}

}  // namespace hgs::test
