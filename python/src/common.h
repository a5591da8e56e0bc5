// Shared helpers of the _hgs extension: numpy arrays that view C++ storage (kept alive by a Python object) or
// take over a std::vector without copying, checks of arrays handed in from Python, and the bind_* entry points
// of the one-file-per-area binding (module.cpp calls them in order).
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "model/gaussian_model.h"
#include "render/renderer.h"
#include "scene/scene.h"

namespace hgs::py {

namespace pb = pybind11;

// A numpy array over `data` (not copied, writable) whose base is `owner`: the array keeps `owner` (the Python
// object holding the C++ storage) alive. Shape in elements, C order.
template <class T>
pb::array view_array(T* data, std::vector<pb::ssize_t> shape, pb::handle owner) {
  return pb::array_t<T>(std::move(shape), data, owner);
}

// The same for storage numpy names by a dtype (IEEE half stored as uint16_t: dtype float16).
inline pb::array view_array(const pb::dtype& dt, void* data, std::vector<pb::ssize_t> shape, pb::handle owner) {
  return pb::array(dt, std::move(shape), {}, data, owner);
}

// The near plane to render a Python model at: `given` when not None, else the model's `near_plane` attribute
// (Model.load and hgs.train set it from the model's config), else render's default 0.01.
inline float model_near_plane_of(pb::handle model, pb::handle given) {
  if (!given.is_none()) return given.cast<float>();
  if (pb::hasattr(model, "near_plane")) return model.attr("near_plane").cast<float>();
  return render::kDefaultNearPlane;
}

// `g` as an hgs.Model whose near_plane attribute is `near_plane` (Model.load, Trainer.model / finish).
inline pb::object model_with_near_plane(std::shared_ptr<GaussianModel> g, float near_plane) {
  pb::object o = pb::cast(std::move(g));
  o.attr("near_plane") = near_plane;
  return o;
}

// A numpy array that takes over `v` (moved into a capsule, no copy of the elements). Shape in elements.
template <class T>
pb::array_t<T> take_vector(std::vector<T>&& v, std::vector<pb::ssize_t> shape) {
  auto* owned = new std::vector<T>(std::move(v));
  pb::capsule cap(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return pb::array_t<T>(std::move(shape), owned->data(), cap);
}

// A float32 array handed in from Python, checked: dtype float32 exactly (no silent conversion) and the given
// shape (-1 = any length there). Throws TypeError / ValueError naming `what`. Returns a C-contiguous copy.
std::vector<float> float32_input(const pb::handle& obj, const std::vector<pb::ssize_t>& shape, const std::string& what,
                                 std::vector<pb::ssize_t>* got_shape = nullptr);

// The index of a view given as an int (negative from the end) or a name / stem; hgs::Error otherwise.
int view_index(const Scene& scene, const pb::handle& view);

// Module parts (one file each).
void bind_errors(pb::module_& m);
void bind_scene(pb::module_& m);
void bind_model(pb::module_& m);
void bind_render(pb::module_& m);
void bind_train(pb::module_& m);
void bind_query(pb::module_& m);
void bind_nets(pb::module_& m);
void bind_synth(pb::module_& m);

}  // namespace hgs::py
