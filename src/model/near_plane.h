// The near plane a model was trained with: MODEL/config.json's `near_plane` (written by `hgs train`, the
// camera-space depth below which Gaussians were culled), so that rendering, evaluation and queries cull as
// training did. A model trained at 0.2 (3DGS's rasterizer) may keep Gaussians nearer than that to a camera which
// training never saw (docs/scaling.md, "The near plane"); rendered at 0.01 they would show.
#pragma once
#include <filesystem>
#include <string>

namespace hgs {

// For a model's PLY path: the config.json beside it, its `near_plane`; render::kDefaultNearPlane when there is
// no config.json or it has no such key (models trained before the key existed). One-line hgs::Error when the file
// is not JSON or the value is not a finite number > 0.
float model_near_plane(const std::filesystem::path& model_ply);

// Checks a near plane given on a command line or in a configuration (finite, > 0); `where` names it in the error.
float checked_near_plane(double value, const std::string& where);

}  // namespace hgs
