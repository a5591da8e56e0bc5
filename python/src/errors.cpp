// Errors across the binding: hgs::Error (the library's one-line user errors) becomes hgs.Error, a RuntimeError
// with the same message; the checks of arrays handed in from Python raise TypeError (dtype) / ValueError (shape).
#include <algorithm>

#include "common.h"
#include "core/error.h"
#include "core/excerpt.h"

namespace hgs::py {

void bind_errors(pb::module_& m) {
  auto& error = pb::register_exception<hgs::Error>(m, "Error", PyExc_RuntimeError);
  error.attr("__module__") = "hgs";  // shown as hgs.Error
  error.doc() = "A user-facing error of the hgs library: a one-line message naming the file or option and the problem";
}

std::vector<float> float32_input(const pb::handle& obj, const std::vector<pb::ssize_t>& shape, const std::string& what,
                                 std::vector<pb::ssize_t>* got_shape) {
  if (!pb::isinstance<pb::array>(obj))
    throw pb::type_error(fmt::format("{}: expected a numpy array of float32, got {}", what,
                                     std::string(pb::str(obj.get_type().attr("__name__")))));
  pb::array a = pb::reinterpret_borrow<pb::array>(obj);
  if (!a.dtype().is(pb::dtype::of<float>()))
    throw pb::type_error(
        fmt::format("{}: expected dtype float32, got {}", what, std::string(pb::str(a.dtype().attr("name")))));
  auto shape_text = [](const std::vector<pb::ssize_t>& s) {
    std::string t;
    for (pb::ssize_t d : s) t += (t.empty() ? "" : ", ") + (d < 0 ? std::string("N") : std::to_string(d));
    return "[" + t + "]";
  };
  std::vector<pb::ssize_t> got(a.shape(), a.shape() + a.ndim());
  bool ok = got.size() == shape.size();
  for (size_t k = 0; ok && k < shape.size(); ++k) ok = shape[k] < 0 || shape[k] == got[k];
  if (!ok)
    throw pb::value_error(fmt::format("{}: expected shape {}, got {}", what, shape_text(shape), shape_text(got)));
  if (got_shape) *got_shape = got;
  auto c = pb::array_t<float, pb::array::c_style>::ensure(a);  // a copy only when not C-contiguous
  return std::vector<float>(c.data(), c.data() + c.size());
}

int view_index(const Scene& scene, const pb::handle& view) {
  const int n = int(scene.views.size());
  if (PyIndex_Check(view.ptr()) && !pb::isinstance<pb::bool_>(view)) {  // int, numpy integers
    auto index = pb::reinterpret_steal<pb::object>(PyNumber_Index(view.ptr()));
    if (!index) {  // e.g. a numpy array of several values
      PyErr_Clear();
      throw pb::type_error("view: expected an index (int) or a name (str), got " + type_name(view));
    }
    const long i = index.cast<long>();
    if (i < -n || i >= n) fail("{}: view {} is out of range (the scene has {} views)", scene.root.string(), i, n);
    return int(i < 0 ? i + n : i);
  }
  if (pb::isinstance<pb::str>(view)) {
    const std::string name = view.cast<std::string>();
    for (const View& v : scene.views)
      if (v.name == name || v.stem == name) return v.index;
    fail("{}: no view named '{}'", scene.root.string(), excerpt(name));
  }
  throw pb::type_error("view: expected an index (int) or a name (str), got " + type_name(view));
}

}  // namespace hgs::py
