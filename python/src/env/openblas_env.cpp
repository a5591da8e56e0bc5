// hgs._openblas_env: the OpenBLAS settings of nn/openblas_env.h for the Python package, in a module of its own
// that does not load OpenBLAS: hgs/__init__.py reads them and puts them in the environment before it imports
// _hgs, whose OpenBLAS reads the environment once, when it is loaded.
#include <pybind11/pybind11.h>

#include "nn/openblas_env.h"

PYBIND11_MODULE(_openblas_env, m) {
  m.doc() = "OPENBLAS_CORETYPE / OPENBLAS_THREAD_TIMEOUT as the hgs executables set them (nn/openblas_env.h)";
  m.def(
      "core_for_this_cpu",
      [] {
        const char* c = hgs::nn::openblas_core_for_this_cpu();
        return c ? pybind11::object(pybind11::str(c)) : pybind11::object(pybind11::none());
      },
      "SkylakeX with AVX-512, Haswell with AVX2 + FMA, else None (the library's own choice)");
  m.attr("thread_timeout") = hgs::nn::kOpenblasThreadTimeout;
}
