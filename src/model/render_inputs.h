// The renderer's read-only view of a GaussianModel: pointers to its mean, scale, rotation, opacity and SH arrays
// (SH at the model's full degree; no extra channels, which methods add themselves).
#pragma once
#include "model/gaussian_model.h"
#include "render/renderer.h"

namespace hgs {

render::GaussianInputs render_inputs(const GaussianModel& m);

}  // namespace hgs
