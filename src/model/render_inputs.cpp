// GaussianModel -> render::GaussianInputs (see render_inputs.h).
#include "model/render_inputs.h"

namespace hgs {

render::GaussianInputs render_inputs(const GaussianModel& m) {
  render::GaussianInputs in;
  in.n = m.n;
  in.mean = m.mean.data();
  in.log_scale = m.log_scale.data();
  in.quat = m.quat.data();
  in.opacity_logit = m.opacity_logit.data();
  in.sh = m.sh.data();
  in.sh_stride = m.sh_stride();
  in.sh_degree = m.sh_degree;
  return in;
}

}  // namespace hgs
