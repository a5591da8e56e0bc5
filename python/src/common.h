// Shared helpers of the _hgs extension: numpy arrays that view C++ storage (kept alive by a Python object) or
// take over a std::vector without copying, checks of arrays handed in from Python, and the bind_* entry points
// of the one-file-per-area binding (module.cpp calls them in order).
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <fmt/format.h>
#include <limits>
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

// Arguments taken as Python objects and converted here, so that a wrong type is a one-line TypeError naming the
// call, the argument and the type expected ("render: scene must be an hgs.Scene, got str") instead of pybind11's
// "Unable to cast Python instance to C++ type" or its multi-line list of signatures.
inline std::string type_name(pb::handle o) { return pb::str(o.get_type().attr("__name__")); }
[[noreturn]] inline void wrong_type(const char* where, const char* name, const char* expected, pb::handle got) {
  throw pb::type_error(fmt::format("{}: {} must be {}, got {}", where, name, expected, type_name(got)));
}
// An instance of a bound class (hgs.Model, hgs.Scene): `expected` names it.
template <class T>
std::shared_ptr<T> object_arg(pb::handle o, const char* where, const char* name, const char* expected) {
  if (!pb::isinstance<T>(o)) wrong_type(where, name, expected, o);
  return o.cast<std::shared_ptr<T>>();
}
// A Python int or float (numpy scalars too; not bool, not str).
inline float float_arg(pb::handle o, const char* where, const char* name) {
  if (pb::isinstance<pb::bool_>(o) || pb::isinstance<pb::str>(o) || !PyNumber_Check(o.ptr()))
    wrong_type(where, name, "a number", o);
  auto f = pb::reinterpret_steal<pb::object>(PyNumber_Float(o.ptr()));
  if (!f) {  // e.g. a numpy array of several values
    PyErr_Clear();
    wrong_type(where, name, "a number", o);
  }
  return float(PyFloat_AsDouble(f.ptr()));
}
// A Python int (numpy integers too; not bool).
inline long long int_arg(pb::handle o, const char* where, const char* name) {
  if (pb::isinstance<pb::bool_>(o) || !PyIndex_Check(o.ptr())) wrong_type(where, name, "an int", o);
  auto i = pb::reinterpret_steal<pb::object>(PyNumber_Index(o.ptr()));
  if (!i) {  // e.g. a numpy array of several values
    PyErr_Clear();
    wrong_type(where, name, "an int", o);
  }
  int overflow = 0;
  const long long v = PyLong_AsLongLongAndOverflow(i.ptr(), &overflow);
  // Beyond long long: the largest / smallest, for the caller's range check to refuse with the range.
  if (overflow != 0)
    return overflow > 0 ? std::numeric_limits<long long>::max() : std::numeric_limits<long long>::min();
  return v;
}
// A dict's key as str.
inline std::string key_arg(pb::handle k, const char* where, const char* name) {
  if (!pb::isinstance<pb::str>(k)) wrong_type(where, name, "str", k);
  return k.cast<std::string>();
}

// The near plane to render a Python model at: `given` when not None, else the model's `near_plane` attribute
// (Model.load and hgs.train set it from the model's config), else render's default 0.01. `where` names the call.
inline float model_near_plane_of(pb::handle model, pb::handle given, const char* where) {
  if (!given.is_none()) return float_arg(given, where, "near_plane");
  if (pb::hasattr(model, "near_plane")) return float_arg(model.attr("near_plane"), where, "near_plane");
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
