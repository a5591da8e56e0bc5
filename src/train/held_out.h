// The held-out score of a model, shared by `hgs render` (per view, with pictures) and `hgs train --test-every`
// (the test curve): PSNR of the render clamped to [0, 1] (the image as saved) and SSIM (3DGS's window), per view.
#pragma once
#include <vector>

#include "core/image.h"
#include "model/gaussian_model.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "train/ssim.h"

namespace hgs::train {

struct ViewScore {
  float psnr = 0, ssim = 0;
};

// rgb [H, W, 3] (the renderer's output) against gt [H, W, 3]; `clamped` receives the render clamped to [0, 1].
ViewScore score_view(const std::vector<float>& rgb, const Image& gt, Image& clamped, SsimWorkspace<float>& ws);

// Renders `model` in each of the scene's views `idx` (background 1 if white else 0, culling at `near_plane`) and
// returns the means of their scores. `images` caches the ground-truth images between calls (filled on the first).
ViewScore score_views(const Scene& scene, const std::vector<int>& idx, const GaussianModel& model, bool white,
                      float near_plane, std::vector<Image>& images);

}  // namespace hgs::train
