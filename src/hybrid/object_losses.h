// The object-conditioned losses of one view: eq. 6 (appearance, (1 - lambda) L1 + lambda (1 - SSIM) of each
// object render I_k against I * M_k) and eq. 14 (BRO on the band of eq. 13, with the scale rule and the
// scale-invariant gradient of bro.h), for the J objects present in the view's mask. The object renders come
// interleaved in the extra channels of one rasterization (object_channels.h); they are copied to planar
// images, each object's losses run single-threaded in one thread's scratch (no parallel-region overhead per
// convolution, each object's images stay in one core's cache), and the gradients go back interleaved.
// Loss values are summed in object order (deterministic).
#pragma once
#include <random>
#include <vector>

#include "core/image.h"
#include "hybrid/config.h"
#include "hybrid/object_channels.h"
#include "train/loss.h"

namespace hgs::hybrid {

struct ObjectLossValues {
  double app = 0;  // mean of eq. 6 over the objects
  double bro = 0;  // mean of eq. 14 over the objects, each weighted by the scale rule (the term as optimised)
};

// The objects scored in one step under HybridConfig::objects_per_step = m: m of `present` [J] drawn uniformly
// without replacement (partial Fisher-Yates on rng), returned in their order in `present`; all of them when m is 0
// or m >= J.
std::vector<int> sample_objects(const std::vector<int>& present, int m, std::mt19937_64& rng);

class ObjectLosses {
 public:
  explicit ObjectLosses(const HybridConfig& cfg) : cfg_(cfg) {}
  // image [H, W, 3]; labels [H, W] (confidence-filtered mask); extra [H, W, C] the render of the layout's
  // channels; objs [J] the objects of the layout. Adds lambda_app * d(app) + lambda_bro * d(bro) to the colour
  // channels of d_extra [H, W, C].
  ObjectLossValues operator()(const Image& image, const LabelMap& labels, const float* extra, const ObjectLayout& lay,
                              const std::vector<int>& objs, float* d_extra);
  void release();

 private:
  struct Scratch {  // per-thread buffers of the losses of one object
    explicit Scratch(float lambda_dssim) : loss(lambda_dssim) {}
    train::PhotometricLoss loss;
    std::vector<float> gt;                 // [H, W, 3]
    std::vector<float> mask, band, morph;  // [H, W]
    std::vector<float> bgrad;              // [H, W, 3] BRO's gradient before its scale component is removed
  };
  HybridConfig cfg_;
  std::vector<Scratch> scratch_;    // [threads]
  std::vector<float> pred_, grad_;  // [J, H, W, 3] planar object renders / gradients
  std::vector<float> opac_;         // [J, H, W]
  std::vector<double> app_, bro_;   // [J]
};

}  // namespace hgs::hybrid
