// The trainer's 3DGS parameters as one table: the name the optimiser and checkpoints know each by, the model
// array it lives in, the gradient array the renderer fills, its column count and its learning rate. Every list of
// them (optimiser registration and value locations, the gradient sum of a batch, the buffer the ranks reduce, the
// Adam updates, the HGS_INJECT_NAN test hook) is derived from this table, in this order.
#pragma once
#include <array>
#include <string>
#include <vector>

#include "model/gaussian_model.h"
#include "render/renderer.h"
#include "train/config.h"

namespace hgs::train {

struct GaussianParam {
  const char* name;
  std::vector<float> GaussianModel::*value;         // [N, cols]
  std::vector<float> render::GaussianGrads::*grad;  // [N, cols]
  int (*cols)(const GaussianModel& m);
  float TrainConfig::*lr;     // the rate of every column, or of columns 3.. when lr_dc is set
  float TrainConfig::*lr_dc;  // the rate of columns 0..2 (the SH DC colour), or null
  bool times_extent;          // the rate scales with the scene extent (positions; decayed per step, position_lr)
};

inline constexpr std::array<GaussianParam, 5> kGaussianParams = {{
    {"mean", &GaussianModel::mean, &render::GaussianGrads::mean, [](const GaussianModel&) { return 3; },
     &TrainConfig::lr_position_init, nullptr, true},
    {"log_scale", &GaussianModel::log_scale, &render::GaussianGrads::log_scale, [](const GaussianModel&) { return 3; },
     &TrainConfig::lr_scaling, nullptr, false},
    {"quat", &GaussianModel::quat, &render::GaussianGrads::quat, [](const GaussianModel&) { return 4; },
     &TrainConfig::lr_rotation, nullptr, false},
    {"opacity", &GaussianModel::opacity_logit, &render::GaussianGrads::opacity_logit,
     [](const GaussianModel&) { return 1; }, &TrainConfig::lr_opacity, nullptr, false},
    {"sh", &GaussianModel::sh, &render::GaussianGrads::sh, [](const GaussianModel& m) { return m.sh_stride() * 3; },
     &TrainConfig::lr_sh_rest, &TrainConfig::lr_sh_dc, false},
}};

// The row of `name`, or null.
inline const GaussianParam* find_gaussian_param(const std::string& name) {
  for (const GaussianParam& p : kGaussianParams)
    if (name == p.name) return &p;
  return nullptr;
}

}  // namespace hgs::train
