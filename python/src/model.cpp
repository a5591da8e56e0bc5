// hgs.Model: a GaussianModel shared with Python. Its arrays are numpy views on the model's own storage (no copy;
// each view's base is the Model, which keeps the storage alive, and writing through a view changes the model):
// means, log_scales, rotations, opacity_logits, sh and every extra group (object_probs = q, language = f in
// float16 or float32). Derived values (scales, opacities, object_ids) are copies. PLY load / save, construction
// from arrays (checked dtype and shapes) and 3D selection by object.
#include <cmath>

#include <nlohmann/json.hpp>

#include "common.h"
#include "core/error.h"
#include "core/folder.h"
#include "core/fs.h"
#include "hybrid/fields.h"
#include "model/near_plane.h"
#include "model/ply.h"
#include "query/query.h"

namespace hgs::py {
namespace {

namespace fs = std::filesystem;
using ModelPtr = std::shared_ptr<GaussianModel>;

fs::path model_file(const fs::path& p) { return fs::is_directory(p) ? p / "point_cloud.ply" : p; }

// A view of an extra group: float32 [N, dim] (dim 1: [N]) or float16 when stored in half precision.
pb::array group_view(ExtraGroup& g, int n, pb::handle self) {
  std::vector<pb::ssize_t> shape = {n};
  if (g.dim > 1) shape.push_back(g.dim);
  if (g.f16) return view_array(pb::dtype("float16"), g.half.data(), shape, self);
  return view_array(g.data.data(), shape, self);
}

// The getter of a property that views one of the model's per-Gaussian float arrays: [N, cols] ([N] for cols 0).
auto field_view(std::vector<float> GaussianModel::*field, int cols) {
  return [field, cols](pb::object self) {
    auto& g = self.cast<GaussianModel&>();
    std::vector<pb::ssize_t> shape = {g.n};
    if (cols > 0) shape.push_back(cols);
    return view_array((g.*field).data(), shape, self);
  };
}

ExtraGroup& group(GaussianModel& m, const char* name) {
  ExtraGroup* g = m.find_extra(name);
  if (!g) fail("the model has no '{}' group (not a hybrid model: train it with method=\"hybrid\")", name);
  return *g;
}

ModelPtr from_arrays(pb::handle means, pb::handle log_scales, pb::handle rotations, pb::handle opacity_logits,
                     pb::handle sh, const pb::dict& extras) {
  auto m = std::make_shared<GaussianModel>();
  std::vector<pb::ssize_t> s;
  m->mean = float32_input(means, {-1, 3}, "means", &s);
  m->n = int(s[0]);
  m->log_scale = float32_input(log_scales, {m->n, 3}, "log_scales");
  m->quat = float32_input(rotations, {m->n, 4}, "rotations");
  m->opacity_logit = float32_input(opacity_logits, {m->n}, "opacity_logits");
  m->sh = float32_input(sh, {m->n, -1, 3}, "sh", &s);
  const int S = int(s[1]), degree = int(std::lround(std::sqrt(double(S)))) - 1;
  if (degree < 0 || degree > 3 || (degree + 1) * (degree + 1) != S)
    throw pb::value_error(fmt::format("sh: {} coefficients per colour is not (degree + 1)^2 for a degree 0..3", S));
  m->sh_degree = degree;
  for (auto [k, v] : extras) {
    const std::string name = key_arg(k, "Model", "extras keys");
    std::vector<pb::ssize_t> es;
    std::vector<float> data = float32_input(v, {m->n, -1}, "extras['" + name + "']", &es);
    ExtraGroup& g = m->add_extra(name, int(es[1]));
    g.data = std::move(data);
  }
  m->validate("hgs.Model");
  return m;
}

// A model derived from `self` (copy, select) keeps the near plane its instance was given (Model.load, hgs.train):
// it is seen from the same cameras.
pb::object derived(const pb::object& self, std::shared_ptr<GaussianModel> g) {
  pb::object o = pb::cast(std::move(g));
  const pb::dict own = self.attr("__dict__");
  if (own.contains("near_plane")) o.attr("near_plane") = own["near_plane"];
  return o;
}

}  // namespace

void bind_model(pb::module_& m) {
  pb::class_<GaussianModel, ModelPtr>(
      m, "Model", pb::dynamic_attr(),
      "Trained 3D Gaussians (plain 3DGS or Hybrid Gaussians). The array properties are views on the model's "
      "storage: writing through them changes the model")
      .def(pb::init(&from_arrays), pb::arg("means"), pb::arg("log_scales"), pb::arg("rotations"),
           pb::arg("opacity_logits"), pb::arg("sh"), pb::arg("extras") = pb::dict(),
           "A model from float32 arrays: means [N, 3], log_scales [N, 3], rotations [N, 4] (w, x, y, z), "
           "opacity_logits [N], sh [N, S, 3] (S = 1, 4, 9 or 16), extras {name: [N, dim]} (copied)")
      .def_static(
          "load",
          [](const fs::path& path) {
            std::shared_ptr<GaussianModel> g;
            float near_plane = 0;
            {
              pb::gil_scoped_release nogil;
              g = std::make_shared<GaussianModel>(read_model_ply(model_file(path)));
              near_plane = model_near_plane(model_file(path));
            }
            return model_with_near_plane(std::move(g), near_plane);
          },
          pb::arg("path"),
          "Reads a model PLY, or MODEL/point_cloud.ply of a model folder; its near_plane attribute is the "
          "config.json's beside it (0.01 without one), which hgs.render and hgs.QuerySession cull at")
      .def(
          "save",
          [](const pb::object& self, const fs::path& path) {
            const GaussianModel& g = self.cast<const GaussianModel&>();
            const float near_plane = float_arg(self.attr("near_plane"), "Model.save", "near_plane");
            fs::path p = path;
            const bool folder = p.extension() != ".ply";
            pb::gil_scoped_release nogil;
            if (!folder) {
              write_model_ply(p, g);
              return p.string();
            }
            // The folder as one change (core/folder.h): killed or interrupted at any moment, it holds the old model
            // or the new one with its config.json, never a PLY alone. A model folder always has its config.json:
            // the training run's when there is one, else the near plane this model is rendered at.
            write_folder_whole(p, [&](const fs::path& tmp) {
              write_model_ply(tmp / "point_cloud.ply", g);
              if (!fs::exists(tmp / "config.json"))
                atomic_write_text(tmp / "config.json", nlohmann::json{{"near_plane", near_plane}}.dump(2) + "\n");
            });
            return (p / "point_cloud.ply").string();
          },
          pb::arg("path"),
          "Writes the model as a 3DGS PLY (atomically): to `path` when it ends in .ply, else to "
          "path/point_cloud.ply with a config.json holding its near_plane unless the folder has one, the folder "
          "replaced as a whole (the other files in it kept); returns the file written. hgs.Error naming the array "
          "when one holds NaN or infinite values (Model.load would refuse the file), and nothing is written")
      .def(
          "copy",
          [](const pb::object& self) {
            return derived(self, std::make_shared<GaussianModel>(self.cast<const GaussianModel&>()));
          },
          "A deep copy (with the instance's near_plane)")
      .def_readonly("n", &GaussianModel::n, "Number of Gaussians N")
      .def("__len__", [](const GaussianModel& g) { return g.n; })
      .def_readonly("sh_degree", &GaussianModel::sh_degree, "SH degree stored (0..3)")
      .def_property_readonly(
          "is_hybrid", [](const GaussianModel& g) { return hybrid::ConstHybridFields::present(g); },
          "Whether the model has object associations and language embeddings (method 'hybrid')")
      .def_property_readonly("method",
                             [](const GaussianModel& g) {
                               return hybrid::ConstHybridFields::present(g) ? "hybrid" : "rgb";
                             })
      .def_property_readonly("means", field_view(&GaussianModel::mean, 3), "Centres float32 [N, 3] (view)")
      .def_property_readonly("log_scales", field_view(&GaussianModel::log_scale, 3),
                             "Log of the scales float32 [N, 3] (view)")
      .def_property_readonly(
          "scales",
          [](const GaussianModel& g) {
            std::vector<float> s(g.log_scale.size());
            for (size_t k = 0; k < s.size(); ++k) s[k] = std::exp(g.log_scale[k]);
            return take_vector(std::move(s), {g.n, 3});
          },
          "Scales float32 [N, 3] (exp of log_scales; a copy)")
      .def_property_readonly("rotations", field_view(&GaussianModel::quat, 4),
                             "Rotations as quaternions (w, x, y, z) float32 [N, 4] (view)")
      .def_property_readonly("opacity_logits", field_view(&GaussianModel::opacity_logit, 0),
                             "Opacity logits float32 [N] (view)")
      .def_property_readonly(
          "opacities",
          [](const GaussianModel& g) {
            std::vector<float> o(g.opacity_logit.size());
            for (size_t k = 0; k < o.size(); ++k) o[k] = sigmoid(g.opacity_logit[k]);
            return take_vector(std::move(o), {g.n});
          },
          "Opacities float32 [N] (sigmoid of the logits; a copy)")
      .def_property_readonly(
          "sh",
          [](pb::object self) {
            auto& g = self.cast<GaussianModel&>();
            return view_array(g.sh.data(), {g.n, g.sh_stride(), 3}, self);
          },
          "Spherical-harmonics coefficients float32 [N, S, 3], coefficient-major (view)")
      .def_property_readonly(
          "object_probs",
          [](pb::object self) {
            auto& g = self.cast<GaussianModel&>();
            return group_view(group(g, hybrid::kAssociationGroup), g.n, self);
          },
          "Hybrid: soft object associations q float32 [N, L], L = objects + 1, column 0 = background (view)")
      .def_property_readonly(
          "object_ids",
          [](GaussianModel& g) {
            const ExtraGroup& z = group(g, hybrid::kHardIdGroup);
            std::vector<int32_t> ids(size_t(g.n));
            for (int i = 0; i < g.n; ++i) ids[i] = int32_t(z.value(size_t(i)));
            return take_vector(std::move(ids), {g.n});
          },
          "Hybrid: hard object ids z = argmax q, int32 [N] (a copy; 0 = background)")
      .def_property_readonly(
          "language",
          [](pb::object self) {
            auto& g = self.cast<GaussianModel&>();
            return group_view(group(g, hybrid::kLanguageGroup), g.n, self);
          },
          "Hybrid: language embeddings f [N, D], float16 (as trained, half storage) or float32 (view)")
      .def_property_readonly(
          "extras",
          [](pb::object self) {
            auto& g = self.cast<GaussianModel&>();
            pb::dict d;
            for (ExtraGroup& e : g.extras) d[pb::str(e.name)] = group_view(e, g.n, self);
            return d;
          },
          "Every extra per-Gaussian group by name (obj = q, obj_id = z, lang = f, ...), as views")
      .def(
          "select",
          [](const pb::object& self, const std::vector<int>& objects, bool remove) {
            const GaussianModel& g = self.cast<const GaussianModel&>();
            std::shared_ptr<GaussianModel> out;
            {
              pb::gil_scoped_release nogil;
              out = std::make_shared<GaussianModel>(query::select_objects(g, objects, remove));
            }
            return derived(self, std::move(out));
          },
          pb::arg("objects"), pb::arg("remove") = false,
          "Hybrid: a copy with the Gaussians whose hard id is one of `objects` (or all others with remove=True), "
          "with the instance's near_plane")
      .def("__repr__", [](const GaussianModel& g) {
        return fmt::format("<hgs.Model {} Gaussians, SH degree {}, {}>", g.n, g.sh_degree,
                           hybrid::ConstHybridFields::present(g) ? "hybrid" : "rgb");
      });
}

}  // namespace hgs::py
