// Gaussian model PLY in the standard 3DGS layout (docs/formats.md, "Model PLY"): binary little endian, one
// `vertex` element with float properties x y z nx ny nz f_dc_0..2 f_rest_0..(3*(S-1)-1) opacity scale_0..2
// rot_0..3, where f_rest is channel-major (all R of coefficients 1..S-1, then G, then B), opacity is the
// logit and scales are logs. Extra channel groups follow rot_3: a group of dim 1 is one property named after
// the group (e.g. `obj_id`), a group of dim D > 1 is `f_<name>_0..f_<name>_{D-1}` (e.g. `f_obj_*`, `f_lang_*`).
#pragma once
#include <filesystem>

#include "model/gaussian_model.h"

namespace hgs {

// Writes atomically. Fails on an invalid model or an extra group name that would not read back.
void write_model_ply(const std::filesystem::path& path, const GaussianModel& model);
// Reads any property order, SH degree 0..3 (f_rest count 0, 9, 24 or 45), property types float/double/
// (u)char/(u)short/(u)int; unknown properties become extra groups. One-line hgs::Error on bad input.
GaussianModel read_model_ply(const std::filesystem::path& path);

}  // namespace hgs
