// The extension module `hgs._hgs`: the C++ library behind the Python package `hgs` (python/hgs/__init__.py wraps
// it; docs/python.md). Each area binds itself from its own file (common.h lists them).
#include "common.h"

PYBIND11_MODULE(_hgs, m) {
  m.doc() = "hgs: Hybrid Gaussians for open-vocabulary 3D segmentation (C++ core; use the package `hgs`)";
  m.attr("__version__") = HGS_VERSION;
  hgs::py::bind_errors(m);
  hgs::py::bind_scene(m);
  hgs::py::bind_model(m);
  hgs::py::bind_render(m);
  hgs::py::bind_train(m);
  hgs::py::bind_query(m);
  hgs::py::bind_nets(m);
  hgs::py::bind_synth(m);
}
