// hgs.render: one view of a scene rendered from a model, as a dict of numpy arrays (each takes over the
// renderer's output vector, no copy): "rgb" float32 [H, W, 3], "alpha" [H, W], "depth" [H, W] (expected depth,
// not divided by alpha), for hybrid models "objects" [H, W, L] (the opacity A_k = sum q_k alpha T of every label,
// column 0 = background) and, on request, "language" [H, W, D] (sum f alpha T). The GIL is released while it
// renders.
#include "common.h"
#include "core/error.h"
#include "hybrid/fields.h"
#include "model/near_plane.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"

namespace hgs::py {
namespace {

struct RenderRequest {
  bool depth = true, objects = true, language = false;
  float background[3] = {0, 0, 0};
  int sh_degree = -1;  // -1 = the model's
  float near_plane = render::kDefaultNearPlane;
};

struct RenderResult {
  int H = 0, W = 0, L = 0, D = 0;
  render::RenderOutputs main;
  std::vector<float> language;  // [H, W, D]
};

RenderResult render_view(const GaussianModel& m, const View& v, const RenderRequest& rq) {
  RenderResult r;
  r.H = v.height, r.W = v.width;
  const bool hybrid = hybrid::ConstHybridFields::present(m);
  if (rq.language && !hybrid) fail("render: language=True needs a hybrid model (this one has no language embeddings)");
  const render::Camera cam = render::camera_from_view(v, rq.near_plane);
  render::GaussianRenderer renderer;
  render::GaussianInputs in = render_inputs(m);
  if (rq.sh_degree >= 0) in.sh_degree = std::min(rq.sh_degree, m.sh_degree);
  render::RenderSettings rs;
  rs.want_depth = rq.depth;
  std::copy_n(rq.background, 3, rs.background);
  if (hybrid && rq.objects) {
    const auto h = hybrid::ConstHybridFields::bind(m, "render");
    in.extra = h.q->data.data();  // q [N, L]: composited as is
    in.num_extra = r.L = h.num_labels;
  }
  renderer.forward(cam, in, rs, r.main);
  if (rq.language) {
    const auto h = hybrid::ConstHybridFields::bind(m, "render");
    r.D = h.dim;
    std::vector<float> f = h.f->to_float();  // [N, D] float32 for the renderer
    in.extra = f.data();
    in.num_extra = r.D;
    rs.want_depth = false;
    render::RenderOutputs lo;
    renderer.forward(cam, in, rs, lo);
    r.language = std::move(lo.extra);
  }
  return r;
}

pb::dict render_py(const GaussianModel& m, const Scene& s, pb::handle view, bool depth, bool objects, bool language,
                   pb::object background, int sh_degree, float near_plane) {
  const int vi = view_index(s, view);
  RenderRequest rq;
  rq.depth = depth, rq.objects = objects, rq.language = language, rq.sh_degree = sh_degree;
  rq.near_plane = checked_near_plane(near_plane, "render: near_plane");
  if (!background.is_none()) {
    std::vector<float> b;
    for (pb::handle x : background) {
      if (pb::isinstance<pb::str>(x) || pb::isinstance<pb::bool_>(x) || !PyNumber_Check(x.ptr()))
        wrong_type("render", "background", "3 numbers (RGB in [0, 1]) or one", background);
      b.push_back(float_arg(x, "render", "background"));
    }
    if (b.size() == 1) b = {b[0], b[0], b[0]};
    if (b.size() != 3) throw pb::value_error("background: expected 3 values (RGB in [0, 1]) or one");
    std::copy_n(b.begin(), 3, rq.background);
  }
  RenderResult r;
  {
    pb::gil_scoped_release nogil;
    r = render_view(m, s.views[vi], rq);
  }
  pb::dict d;
  d["rgb"] = take_vector(std::move(r.main.rgb), {r.H, r.W, 3});
  d["alpha"] = take_vector(std::move(r.main.alpha), {r.H, r.W});
  if (depth) d["depth"] = take_vector(std::move(r.main.depth), {r.H, r.W});
  if (r.L > 0) d["objects"] = take_vector(std::move(r.main.extra), {r.H, r.W, r.L});
  if (language) d["language"] = take_vector(std::move(r.language), {r.H, r.W, r.D});
  return d;
}

// Python's float sequence for the background: a list, tuple or a number.
pb::object as_background(pb::object b) {
  if (b.is_none() || (pb::isinstance<pb::sequence>(b) && !pb::isinstance<pb::str>(b))) return b;
  if (pb::isinstance<pb::str>(b) || pb::isinstance<pb::bool_>(b) || !PyNumber_Check(b.ptr()))
    wrong_type("render", "background", "3 numbers (RGB in [0, 1]) or one", b);
  return pb::make_tuple(b);
}

}  // namespace

void bind_render(pb::module_& m) {
  m.def(
      "render",
      [](pb::object model, pb::object scene, pb::handle view, bool depth, bool objects, bool language,
         pb::object background, pb::object sh_degree, pb::object near_plane) {
        const auto m = object_arg<GaussianModel>(model, "render", "model", "an hgs.Model");
        const auto s = object_arg<Scene>(scene, "render", "scene", "an hgs.Scene");
        const long long sh = int_arg(sh_degree, "render", "sh_degree");
        if (sh < -1 || sh > 3) throw pb::value_error(fmt::format("render: sh_degree must be -1..3, got {}", sh));
        return render_py(*m, *s, view, depth, objects, language, as_background(background), int(sh),
                         model_near_plane_of(model, near_plane, "render"));
      },
      pb::arg("model"), pb::arg("scene"), pb::arg("view"), pb::kw_only(), pb::arg("depth") = true,
      pb::arg("objects") = true, pb::arg("language") = false, pb::arg("background") = pb::none(),
      pb::arg("sh_degree") = pb::int_(-1), pb::arg("near_plane") = pb::none(),
      "Renders view `view` (index or name) of `scene`. Returns a dict of numpy arrays: rgb float32 [H, W, 3], "
      "alpha [H, W], depth [H, W]; for hybrid models objects [H, W, L] (per-label opacity, column 0 = background) "
      "and, with language=True, language [H, W, D]. background: RGB in [0, 1] (default black); sh_degree: "
      "the SH degree used (-1 = the model's); near_plane: cull Gaussians nearer than this to the camera (default: "
      "the model's near_plane attribute, set by Model.load and hgs.train, else 0.01)");
}

}  // namespace hgs::py
