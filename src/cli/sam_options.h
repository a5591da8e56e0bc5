// The SAM model options shared by `hgs masks generate` and `hgs masks click`: --vit-heads, --precision and
// --decoder-heads, and the model they load.
#pragma once
#include <CLI/CLI.hpp>
#include <string>

#include "nn/gemm_bf16.h"
#include "sam/model.h"

namespace hgs::cli {

struct SamModelOptions {
  int vit_heads = 0, decoder_heads = 0;
  std::string precision = "f32";

  void add_to(CLI::App& sub) {
    sub.add_option("--vit-heads", vit_heads,
                   "Image encoder heads per layer (0 = from the relative-position tables, else config.json; given, "
                   "it must agree with the tables and serves layers without them)")
        ->check(CLI::Range(0, 4096))
        ->capture_default_str();
    sub.add_option("--precision", precision,
                   "f32 (exact) or bf16: the large matrix products in bfloat16 with float32 sums, 2-4x faster with "
                   "AMX / AVX512-BF16 (an approximation: docs/sam.md)")
        ->check(CLI::IsMember({"f32", "bf16"}))
        ->capture_default_str();
    sub.add_option("--decoder-heads", decoder_heads, "Mask decoder heads (0 = config.json beside the weights, else 8)")
        ->capture_default_str();
  }
  sam::SamModel load(const std::string& weights) const {
    return sam::SamModel::load(weights, {decoder_heads, vit_heads, nn::parse_precision(precision, "--precision")});
  }
};

}  // namespace hgs::cli
