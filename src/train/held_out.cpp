#include "train/held_out.h"

#include <algorithm>

#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "train/loss.h"

namespace hgs::train {

ViewScore score_view(const std::vector<float>& rgb, const Image& gt, Image& clamped, SsimWorkspace<float>& ws) {
  clamped = Image(gt.width, gt.height, 3);
  double se = 0;
  for (size_t i = 0; i < clamped.px.size(); ++i) {
    clamped.px[i] = std::clamp(rgb[i], 0.f, 1.f);
    se += double(clamped.px[i] - gt.px[i]) * (clamped.px[i] - gt.px[i]);
  }
  ViewScore s;
  s.psnr = psnr_from_mse(se / double(clamped.px.size()));
  s.ssim = ssim(clamped.px.data(), gt.px.data(), gt.height, gt.width, 3, (float*)nullptr, ws);
  return s;
}

ViewScore score_views(const Scene& scene, const std::vector<int>& idx, const GaussianModel& model, bool white,
                      float near_plane, std::vector<Image>& images) {
  if (images.size() != idx.size()) {
    images.clear();
    for (int i : idx) images.push_back(scene.load_image(i));
  }
  render::GaussianRenderer renderer;
  render::RenderOutputs ro;
  const render::GaussianInputs in = render_inputs(model);
  render::RenderSettings rs;
  rs.want_depth = false;
  rs.background[0] = rs.background[1] = rs.background[2] = white ? 1.f : 0.f;
  SsimWorkspace<float> ws;
  Image clamped;
  double psnr = 0, ssim = 0;
  for (size_t k = 0; k < idx.size(); ++k) {
    renderer.forward(render::camera_from_view(scene.views[idx[k]], near_plane), in, rs, ro);
    const ViewScore s = score_view(ro.rgb, images[k], clamped, ws);
    psnr += s.psnr;
    ssim += s.ssim;
  }
  ViewScore m;
  if (!idx.empty()) m.psnr = float(psnr / double(idx.size())), m.ssim = float(ssim / double(idx.size()));
  return m;
}

}  // namespace hgs::train
