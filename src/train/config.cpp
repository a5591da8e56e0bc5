// TrainConfig helpers: schedule scaling, the 3DGS exponential position-lr schedule, JSON round trip.
#include "train/config.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/json_number.h"

namespace hgs::train {

TrainConfig TrainConfig::scaled_to(int iterations) const {
  TrainConfig c = *this;
  const double f = double(iterations) / 30000.0;
  auto sc = [&](int v) { return std::max(1, int(std::lround(v * f))); };
  c.iters = iterations;
  c.densify_until = sc(densify_until);
  c.densify_every = std::max(sc(densify_every), densify_every);
  c.densify_from = std::max(sc(densify_from), std::min(densify_from, iterations / 10));
  c.opacity_reset_every = std::max(sc(opacity_reset_every), 10 * c.densify_every);
  return c;
}

float TrainConfig::position_lr(int it, float extent) const {
  double t = std::clamp(double(it) / double(std::max(1, iters)), 0.0, 1.0);
  double a = std::log(double(lr_position_init) * extent), b = std::log(double(lr_position_final) * extent);
  return float(std::exp(a * (1 - t) + b * t));
}

nlohmann::json TrainConfig::to_json() const {
  return {{"method", method},
          {"iters", iters},
          {"sh_degree", sh_degree},
          {"densify", densify},
          {"white_bg", white_bg},
          {"near_plane", near_plane},
          {"seed", seed},
          {"lambda_dssim", lambda_dssim},
          {"lr_position_init", lr_position_init},
          {"lr_position_final", lr_position_final},
          {"lr_sh_dc", lr_sh_dc},
          {"lr_sh_rest", lr_sh_rest},
          {"lr_opacity", lr_opacity},
          {"lr_scaling", lr_scaling},
          {"lr_rotation", lr_rotation},
          {"sh_increase_every", sh_increase_every},
          {"densify_from", densify_from},
          {"densify_until", densify_until},
          {"densify_every", densify_every},
          {"opacity_reset_every", opacity_reset_every},
          {"screen_limit", screen_limit},
          {"late_prune", late_prune},
          {"densify_grad_threshold", densify_cfg.grad_threshold},
          {"percent_dense", densify_cfg.percent_dense},
          {"min_opacity", densify_cfg.min_opacity},
          {"max_world_scale", densify_cfg.max_world_scale},
          {"save_every", save_every},
          {"batch", batch},
          {"batch_lr", batch_lr}};
}

bool is_batch_lr_rule(const std::string& r) { return r == "none" || r == "sqrt" || r == "sqrt-rates"; }

TrainConfig TrainConfig::from_json(const nlohmann::json& j, const std::string& where) {
  TrainConfig c;
  if (!j.is_object()) fail("{}: training configuration is not a JSON object", where);
  auto get = [&](const char* key, auto& dst) {
    if (!j.contains(key)) return;
    using T = std::decay_t<decltype(dst)>;
    if constexpr (std::is_arithmetic_v<T>) {  // range-checked (json_number.h)
      const std::optional<T> v = json_number<T>(j.at(key));
      if (!v) fail("{}: '{}' has the wrong type or is out of range", where, key);
      dst = *v;
      return;
    }
    try {
      j.at(key).get_to(dst);
    } catch (const std::exception&) {
      fail("{}: '{}' has the wrong type", where, key);
    }
  };
  get("method", c.method);
  get("iters", c.iters);
  get("sh_degree", c.sh_degree);
  get("densify", c.densify);
  get("white_bg", c.white_bg);
  get("near_plane", c.near_plane);
  if (!(c.near_plane > 0) || !std::isfinite(c.near_plane))
    fail("{}: 'near_plane' must be a number > 0, got {}", where, c.near_plane);
  get("seed", c.seed);
  get("lambda_dssim", c.lambda_dssim);
  get("lr_position_init", c.lr_position_init);
  get("lr_position_final", c.lr_position_final);
  get("lr_sh_dc", c.lr_sh_dc);
  get("lr_sh_rest", c.lr_sh_rest);
  get("lr_opacity", c.lr_opacity);
  get("lr_scaling", c.lr_scaling);
  get("lr_rotation", c.lr_rotation);
  get("sh_increase_every", c.sh_increase_every);
  get("densify_from", c.densify_from);
  get("densify_until", c.densify_until);
  get("densify_every", c.densify_every);
  get("opacity_reset_every", c.opacity_reset_every);
  get("screen_limit", c.screen_limit);
  get("late_prune", c.late_prune);
  if (!(c.late_prune >= 0)) fail("{}: 'late_prune' must be >= 0, got {}", where, c.late_prune);
  get("densify_grad_threshold", c.densify_cfg.grad_threshold);
  get("percent_dense", c.densify_cfg.percent_dense);
  get("min_opacity", c.densify_cfg.min_opacity);
  get("max_world_scale", c.densify_cfg.max_world_scale);
  get("save_every", c.save_every);
  get("batch", c.batch);
  if (c.batch < 1 || c.batch > 4096) fail("{}: 'batch' must be 1..4096, got {}", where, c.batch);
  get("batch_lr", c.batch_lr);
  if (!is_batch_lr_rule(c.batch_lr))
    fail("{}: 'batch_lr' must be none, sqrt or sqrt-rates, got '{}'", where, c.batch_lr);
  return c;
}

}  // namespace hgs::train
